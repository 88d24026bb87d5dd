"""Hostile input, round 3 (issue 45, seen 4): a bundle whose manifest, or whose signature, is nested
brackets made `vascsim import-bundle` print a RecursionError traceback."""

from __future__ import annotations

import hashlib
import zipfile

from click.testing import CliRunner

from sessions.cli import main

DEEP = b"[" * 100_000 + b"]" * 100_000


def _bundle(path, manifest: bytes, signature: bytes | None = None):
    with zipfile.ZipFile(path, "w") as archive:
        archive.writestr("manifest.json", manifest)
        archive.writestr("manifest.sha256", hashlib.sha256(manifest).hexdigest() + "\n")
        if signature is not None:
            archive.writestr("manifest.sig", signature)
    return path


def test_nested_manifest_or_signature_is_a_one_line_refusal(home, tmp_path):
    runner = CliRunner()
    deep = _bundle(tmp_path / "deep.zip", DEEP)
    result = runner.invoke(main, ["import-bundle", str(deep)])
    assert result.exit_code == 1 and "Traceback" not in result.output, result.output
    assert "nests arrays or objects deeper than" in result.output and result.output.count("\n") == 1
    key = tmp_path / "site.key"
    assert runner.invoke(main, ["keys", "new", str(key)]).exit_code == 0
    nested = b"[" * 2000 + b"]" * 2000  # under the signature's 4 kB limit, over the parser's recursion
    signed = _bundle(tmp_path / "sig.zip", b'{"format": "vascsim-study-bundle"}', nested)
    result = runner.invoke(main, ["import-bundle", str(signed), "--trust", f"{key}.pub"])
    assert result.exit_code == 1 and "Traceback" not in result.output, result.output
    assert "its signature file is not a vascsim signature" in result.output
    assert result.output.count("\n") == 1


def test_a_member_named_twice_is_refused_before_anything_is_read(home, tmp_path):
    """Seen 4: duplicate zip member names were accepted (the last copy was read)."""
    import warnings

    manifest = b'{"format": "vascsim-study-bundle"}'
    path = _bundle(tmp_path / "twice.zip", manifest)
    with warnings.catch_warnings(), zipfile.ZipFile(path, "a") as archive:
        warnings.simplefilter("ignore")  # zipfile warns about the duplicate name it is asked to write
        archive.writestr("manifest.json", b'{"format": "something else"}')
    result = CliRunner().invoke(main, ["import-bundle", str(path)])
    assert result.exit_code == 1 and "holds manifest.json more than once" in result.output, result.output
    assert result.output.count("\n") == 1
