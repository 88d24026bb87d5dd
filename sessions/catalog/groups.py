"""Who a participant is compared as: a closed, case-insensitive vocabulary of groups.

A study's analysis compares two groups (experts against trainees by default), so a label typed as
"Trainee" or "trainees" must not quietly make a third group nobody analyses. The standard groups are
:data:`STANDARD_GROUPS`; a study may declare more (``vascsim studies groups STUDY --add fellow``).
Labels are stored lower-case; anything else is refused with the list.
"""

from __future__ import annotations

import re
from collections.abc import Iterable

from sessions.catalog.errors import CatalogError

STANDARD_GROUPS = ("expert", "intermediate", "trainee", "novice")
"""The groups every study knows, most skilled first."""

_NAME = re.compile(r"^[a-z][a-z0-9 _-]{0,31}$")


def known_groups(custom: Iterable[str] = ()) -> tuple[str, ...]:
    """The standard groups, then the study's declared ones."""
    return STANDARD_GROUPS + tuple(g for g in custom if g not in STANDARD_GROUPS)


def group_name(label: str, custom: Iterable[str] = (), what: str = "group", study: str = "STUDY") -> str:
    """``label`` as stored: lower-case and one of :func:`known_groups` ("" stays "": no group given).
    Anything else is a CatalogError naming the label and listing the groups (its remedy: declare
    another group in ``study``)."""
    name = " ".join(str(label).split()).lower()
    if not name:
        return ""
    known = known_groups(custom)
    if name not in known:
        raise CatalogError(
            f"unknown {what} {label!r}; the study's groups are {', '.join(known)}",
            remedy=("declare-group", study),
        )
    return name


def declared_group(name: str) -> str:
    """A new custom group's name, checked: lower-case letters, digits, spaces, '-' or '_', at most 32."""
    clean = " ".join(str(name).split()).lower()
    if not _NAME.match(clean):
        raise CatalogError(
            f"group name {name!r} must start with a letter and hold only letters, digits, spaces, "
            "'-' or '_' (at most 32 characters)"
        )
    return clean


def study_groups(catalog, study_name: str, add: Iterable[str] = ()) -> tuple[str, ...]:
    """The groups study ``study_name`` knows, after declaring ``add`` (kept lower-case, each once)."""
    with catalog.session() as orm:
        study = catalog.study(orm, study_name)
        custom = list(study.custom_groups or ())
        for name in add:
            clean = declared_group(name)
            if clean not in STANDARD_GROUPS and clean not in custom:
                custom.append(clean)
        if custom != list(study.custom_groups or ()):
            study.custom_groups = custom
        return known_groups(custom)
