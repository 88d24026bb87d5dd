"""Ed25519 signatures on study bundles: which site exported a study, and that nobody changed it.

A site makes one key pair (``vascsim keys new site.key``: the private key, readable by its
owner only, and ``site.key.pub`` to hand out). ``vascsim export --sign site.key`` signs the
bundle's manifest, which holds every stream file's SHA-256, so the signature covers the
files too. ``vascsim import-bundle --trust site.key.pub`` refuses a bundle that is unsigned,
signed by another key, or changed after signing.
"""

from __future__ import annotations

import base64
import hashlib
import json
import os
from pathlib import Path

from recorder.json_input import parse_json
from sessions.catalog import CatalogError

SIGNATURE = "manifest.sig"
ALGORITHM = "ed25519"


def new_key_pair(path: str | Path) -> tuple[Path, Path]:
    """Write a new private key to ``path`` (PEM, mode 0600) and its public key to ``path.pub``."""
    from cryptography.hazmat.primitives import serialization
    from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey

    path = Path(path)
    public = path.with_name(path.name + ".pub")
    for target in (path, public):
        if target.exists():
            raise CatalogError(f"{target} already exists; choose another name or move it away")
    key = Ed25519PrivateKey.generate()
    private_pem = key.private_bytes(
        serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8, serialization.NoEncryption()
    )
    descriptor = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    with os.fdopen(descriptor, "wb") as handle:
        handle.write(private_pem)
    public.write_bytes(
        key.public_key().public_bytes(
            serialization.Encoding.PEM, serialization.PublicFormat.SubjectPublicKeyInfo
        )
    )
    return path, public


def _private_key(path: Path):
    from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey
    from cryptography.hazmat.primitives.serialization import load_pem_private_key

    try:
        key = load_pem_private_key(path.read_bytes(), password=None)
    except (OSError, ValueError, TypeError) as error:
        raise CatalogError(
            f"signing key {path} cannot be read as an unencrypted PEM private key ({error})"
        ) from None
    if not isinstance(key, Ed25519PrivateKey):
        raise CatalogError(f"signing key {path} is not an Ed25519 key", remedy=("new-key", str(path)))
    return key


def _public_key(path: Path):
    from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PublicKey
    from cryptography.hazmat.primitives.serialization import load_pem_public_key

    try:
        key = load_pem_public_key(path.read_bytes())
    except (OSError, ValueError, TypeError) as error:
        raise CatalogError(f"trusted key {path} cannot be read as a PEM public key ({error})") from None
    if not isinstance(key, Ed25519PublicKey):
        raise CatalogError(f"trusted key {path} is not an Ed25519 public key")
    return key


def fingerprint(public_key) -> str:
    """SHA-256 of the raw public key, 16 hex digits: names a key in messages."""
    from cryptography.hazmat.primitives import serialization

    raw = public_key.public_bytes(serialization.Encoding.Raw, serialization.PublicFormat.Raw)
    return hashlib.sha256(raw).hexdigest()[:16]


def trusted_fingerprint(path: str | Path) -> str:
    """The fingerprint of the public key in ``path``."""
    return fingerprint(_public_key(Path(path)))


def sign(manifest: bytes, key_path: str | Path) -> bytes:
    """The content of a bundle's ``manifest.sig`` for ``manifest`` signed with the key at ``key_path``."""
    key = _private_key(Path(key_path))
    signature = key.sign(manifest)
    record = {
        "algorithm": ALGORITHM,
        "key": fingerprint(key.public_key()),
        "signature": base64.b64encode(signature).decode(),
    }
    return json.dumps(record, sort_keys=True).encode() + b"\n"


def verify(manifest: bytes, signature: bytes | None, trusted: str | Path, bundle: str | Path) -> str:
    """Check ``signature`` (``manifest.sig``'s content, None if absent) against the trusted public key;
    returns the key's fingerprint. CatalogError naming the bundle when it does not verify."""
    from cryptography.exceptions import InvalidSignature

    key = _public_key(Path(trusted))
    expected = fingerprint(key)
    if signature is None:
        raise CatalogError(f"bundle {bundle} is not signed; the trusted key {expected} requires a signature")
    try:
        record = parse_json(signature, "manifest.sig")
        stated = base64.b64decode(record["signature"], validate=True)
        algorithm, signer = record["algorithm"], record["key"]
    except (ValueError, KeyError, TypeError):
        raise CatalogError(f"bundle {bundle}: its signature file is not a vascsim signature") from None
    if algorithm != ALGORITHM or signer != expected:
        raise CatalogError(f"bundle {bundle} is signed by key {signer!r}, not by the trusted key {expected}")
    try:
        key.verify(stated, manifest)
    except InvalidSignature:
        raise CatalogError(
            f"bundle {bundle} was changed after it was signed (signature does not verify)"
        ) from None
    return expected
