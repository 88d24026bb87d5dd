"""Study bundles: export then import reproduces identical metrics; bad bundles change nothing."""

import json
import zipfile
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

from metrics import from_recorded, metrics_of
from metrics.tissue import with_tissue_fields
from recorder import open_session
from sessions.bundle import export_study, import_bundle
from sessions.catalog import CatalogError
from sessions.cli import main
from sessions.runner import study_table
from sessions.tasks import session_tissue


def invoke(*args):
    return CliRunner().invoke(main, list(args), catch_exceptions=False)


@pytest.fixture
def small_study(home):
    """A study of two participants with three scored sessions, through the real CLI."""
    invoke("studies", "add", "course")
    for code, level, skill in (("E1", "expert", "1.0"), ("T1", "trainee", "0.2")):
        assert invoke("participants", "add", code, "--study", "course", "--level", level).exit_code == 0
        for _ in range(1 if code == "E1" else 2):
            result = invoke("run", "--study", "course", "--participant", code, "--skill", skill)
            assert result.exit_code == 0, result.output
    return home


def _sessions_on_disk(home: Path) -> list[str]:
    folder = home / "sessions"
    return sorted(p.name for p in folder.iterdir()) if folder.exists() else []


@pytest.mark.slow
def test_export_then_import_elsewhere_reproduces_identical_metrics(small_study, tmp_path, open_catalog):
    from sessions.config import database_url

    source = open_catalog(database_url(small_study))  # closed at teardown even if an assert fails
    bundle = tmp_path / "course.vascsim.zip"
    summary = export_study(source, "course", bundle)
    # header, samples, events, scene per session
    assert summary["sessions"] == 3 and summary["files"] == 12
    before = study_table(source, "course")
    # a second machine: another data directory, always an embedded SQLite catalog
    other_home = tmp_path / "other"
    target = open_catalog(f"sqlite:///{tmp_path / 'other.sqlite'}")
    assert import_bundle(target, other_home, bundle) == {"study": "course", "sessions": 3, "participants": 2}
    after = study_table(target, "course")
    pd.testing.assert_frame_equal(before, after)
    # the imported stream files give exactly the stored metrics again
    for uid in after["session_id"]:
        streams = from_recorded(open_session(other_home / "sessions" / uid))
        direct = metrics_of(with_tissue_fields(streams, session_tissue(streams, other_home / "cache")))
        stored = after.set_index("session_id").loc[uid, list(direct)]
        np.testing.assert_array_equal(np.asarray(stored, float), np.asarray(list(direct.values()), float))
    with pytest.raises(CatalogError, match="already exists; this bundle was already imported"):
        import_bundle(target, other_home, bundle)


def _rewrite(bundle: Path, out: Path, change) -> None:
    with zipfile.ZipFile(bundle) as source, zipfile.ZipFile(out, "w") as target:
        for info in source.infolist():
            target.writestr(info.filename, change(info.filename, source.read(info.filename)))


@pytest.mark.slow
def test_corrupted_or_hostile_bundles_are_one_line_errors_and_change_nothing(small_study, tmp_path):
    bundle = tmp_path / "course.zip"
    assert invoke("export", "--study", "course", "-o", str(bundle)).exit_code == 0
    invoke(
        "sessions", "delete", "--yes", json.loads(invoke("sessions", "list", "--json").stdout)[0]["session"]
    )
    listed = invoke("sessions", "list", "--json").stdout
    on_disk = _sessions_on_disk(small_study)

    def flip_parquet_byte(name, data):
        if name.endswith("samples.parquet") and not hasattr(flip_parquet_byte, "done"):
            flip_parquet_byte.done = True
            return data[:100] + bytes([data[100] ^ 0xFF]) + data[101:]
        return data

    def tamper_manifest(name, data):
        return data.replace(b'"trial": 1', b'"trial": 9') if name == "manifest.json" else data

    def escape_directory(name, data):
        if name in ("manifest.json", "manifest.sha256"):
            import hashlib

            text = json.loads(source_manifest)
            text["study"]["name"] = "elsewhere"
            text["sessions"][0]["files"][0]["name"] = "../../escape"
            raw = json.dumps(text).encode()
            return raw if name == "manifest.json" else hashlib.sha256(raw).hexdigest().encode()
        return data

    with zipfile.ZipFile(bundle) as archive:
        source_manifest = archive.read("manifest.json")
    truncated = tmp_path / "truncated.zip"
    truncated.write_bytes(bundle.read_bytes()[: bundle.stat().st_size // 2])
    cases = {truncated: "is not a readable vascsim study bundle"}
    for change, message in (
        (flip_parquet_byte, "is corrupted"),
        (tamper_manifest, "manifest does not match its checksum"),
        (escape_directory, "that is not a plain name"),
    ):
        out = tmp_path / f"{change.__name__}.zip"
        _rewrite(bundle, out, change)
        cases[out] = message
    cases[tmp_path / "absent.zip"] = "does not exist"
    cases[bundle] = "already exists"  # the study is still there (one session fewer)
    for path, message in cases.items():
        result = CliRunner().invoke(main, ["import-bundle", str(path)])
        assert result.exit_code == 1, (path, result.output)
        assert message in result.output and "Traceback" not in result.output, (path, result.output)
        assert result.output.count("\n") == 1
        assert invoke("sessions", "list", "--json").stdout == listed
        assert _sessions_on_disk(small_study) == on_disk
    # an edited stream file is refused on the way out too
    uid = json.loads(listed)[0]["session"]
    samples = small_study / "sessions" / uid / "samples.parquet"
    samples.write_bytes(samples.read_bytes() + b"\0")
    result = CliRunner().invoke(main, ["export", "--study", "course", "-o", str(tmp_path / "again.zip")])
    assert result.exit_code == 1 and "no longer matches its catalogued SHA-256" in result.output
    assert not (tmp_path / "again.zip").exists() and not (tmp_path / "again.zip.partial").exists()


def _rehashed(bundle: Path, out: Path, edit) -> None:
    """A bundle whose manifest someone edited and re-checksummed: the checksum proves nothing."""
    import hashlib

    with zipfile.ZipFile(bundle) as archive:
        manifest = json.loads(archive.read("manifest.json"))
    edit(manifest)
    raw = json.dumps(manifest).encode()

    def change(name, data):
        if name == "manifest.json":
            return raw
        return hashlib.sha256(raw).hexdigest().encode() if name == "manifest.sha256" else data

    _rewrite(bundle, out, change)


@pytest.mark.slow
def test_the_declared_analysis_travels_with_the_bundle_and_is_checked(small_study, tmp_path, open_catalog):
    from sessions.analysis import analysis_history, declared_settings
    from sessions.config import database_url

    declared = invoke("studies", "analysis", "course", "--rule", "median", "--by", "alice", "--note", "v1")
    assert declared.exit_code == 0, declared.output
    source = open_catalog(database_url(small_study))
    bundle = tmp_path / "course.zip"
    export_study(source, "course", bundle)
    target = open_catalog(f"sqlite:///{tmp_path / 'other.sqlite'}")
    for edit, message in (
        (
            lambda m: m["analyses"][0]["settings"].update(benchmark_rule="best"),
            r"analyses\[0\].*benchmark rule",
        ),
        (lambda m: m["analyses"][0]["settings"].update(metrics=["rm -rf"]), r"unknown metric 'rm -rf'"),
        (lambda m: m["analyses"][0].update(version=True), "version must be a whole number"),
        (lambda m: m["analyses"][0].update(created_at=None), "is not an ISO time"),
        (
            lambda m: m["analyses"].append(dict(m["analyses"][0])),
            r"versions must run 1, 2, \.\.\.; got \[1, 1\]",
        ),
        (lambda m: m.update(analyses={"version": 1}), "must be a list"),
    ):
        hostile = tmp_path / "hostile.zip"
        _rehashed(bundle, hostile, edit)
        with pytest.raises(CatalogError, match=message):
            import_bundle(target, tmp_path / "other", hostile)
        with target.session() as orm:
            from sessions.models import Study

            assert orm.query(Study).count() == 0  # refused before anything was stored
    import_bundle(target, tmp_path / "other", bundle)
    assert declared_settings(target, "course")[:2] == declared_settings(source, "course")[:2]
    assert analysis_history(target, "course") == analysis_history(source, "course")
