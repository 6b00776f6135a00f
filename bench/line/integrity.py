"""Records that cannot be edited unseen: each unit record's SHA-256 over its canonical JSON, chained
per station (each record holds the previous record's hash and its place in the chain) and signed
with the station's Ed25519 key (the `cryptography` package; the key file is named by the station
file's `[station] line_key`, never kept in the repository).

The hash covers the whole record but `integrity` (the hash and signature themselves),
`record_file` (where the file lies) and `db_error` (a note added when the database refused it):
any other edit, a verdict, a value, a serial, breaks it.  docs/line.md says how to make a key."""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import json
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from . import LineError

UNHASHED = ("integrity", "record_file", "db_error")
ALGORITHM = "ed25519"


def canonical(record: dict[str, Any]) -> bytes:
    """The bytes the record's hash is taken over: sorted keys, no spaces, UTF-8."""
    body = {k: v for k, v in record.items() if k not in UNHASHED}
    return json.dumps(body, sort_keys=True, separators=(",", ":"), ensure_ascii=False).encode()


def record_hash(record: dict[str, Any]) -> str:
    """The record's SHA-256 (hex) over its canonical JSON."""
    return hashlib.sha256(canonical(record)).hexdigest()


# --- keys ----------------------------------------------------------------------------------------
def key_id(public_hex: str) -> str:
    """A short name of a public key: the first 16 hex digits of its SHA-256."""
    return hashlib.sha256(bytes.fromhex(public_hex)).hexdigest()[:16]


class Signer:
    """A station's private key (Ed25519), read from its PEM file."""

    def __init__(self, path: str | Path) -> None:
        from cryptography.hazmat.primitives import serialization
        from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey

        self.path = Path(path)
        try:
            key = serialization.load_pem_private_key(self.path.read_bytes(), password=None)
        except OSError as exc:
            raise LineError(f"line key {self.path}: cannot be read ({exc.strerror or exc})") from None
        except (ValueError, TypeError) as exc:
            raise LineError(f"line key {self.path}: not an unencrypted PEM private key ({exc})") from None
        if not isinstance(key, Ed25519PrivateKey):
            raise LineError(f"line key {self.path}: a {type(key).__name__}, not an Ed25519 key")
        self._key = key
        raw = key.public_key().public_bytes(serialization.Encoding.Raw, serialization.PublicFormat.Raw)
        self.public_hex = raw.hex()
        self.key_id = key_id(self.public_hex)

    def sign(self, digest_hex: str) -> str:
        return self._key.sign(bytes.fromhex(digest_hex)).hex()


def generate_key(path: str | Path) -> tuple[Path, Path]:
    """A new Ed25519 key: the private PEM at path (mode 0600, never overwritten) and its public PEM
    at path + '.pub' (what `line verify --key` and `line import --key` trust)."""
    from cryptography.hazmat.primitives import serialization
    from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey

    path = Path(path)
    key = Ed25519PrivateKey.generate()
    pem = key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                            serialization.NoEncryption())
    try:
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    except FileExistsError:
        raise LineError(f"{path}: already exists (a key is never overwritten)") from None
    with os.fdopen(fd, "wb") as f:
        f.write(pem)
    pub = path.with_name(path.name + ".pub")
    pub.write_bytes(key.public_key().public_bytes(serialization.Encoding.PEM,
                                                  serialization.PublicFormat.SubjectPublicKeyInfo))
    return path, pub


def load_public_key(path: str | Path) -> str:
    """A trusted public key file (PEM, as `generate_key` writes it) as raw hex."""
    from cryptography.hazmat.primitives import serialization
    from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PublicKey

    try:
        key = serialization.load_pem_public_key(Path(path).read_bytes())
    except OSError as exc:
        raise LineError(f"public key {path}: cannot be read ({exc.strerror or exc})") from None
    except ValueError as exc:
        raise LineError(f"public key {path}: not a PEM public key ({exc})") from None
    if not isinstance(key, Ed25519PublicKey):
        raise LineError(f"public key {path}: not an Ed25519 key")
    return key.public_bytes(serialization.Encoding.Raw, serialization.PublicFormat.Raw).hex()


def station_signer(config: Any) -> Signer | None:
    """The signer a station file names (`[station] line_key`, relative to the file), or None."""
    name = (getattr(config, "station", None) or {}).get("line_key") or ""
    if not name:
        return None
    path = Path(name).expanduser()
    if not path.is_absolute():
        path = Path(config.source).resolve().parent / path
    return Signer(path)


# --- the chain -----------------------------------------------------------------------------------
def _safe(text: str) -> str:
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in text) or "station"


class Chain:
    """A station's chain head (its last record's index and hash) in RUNS_DIR/line/chain/STATION.json,
    held under a file lock while a record is sealed and written (two processes of one station)."""

    def __init__(self, runs_dir: str | Path, station: str) -> None:
        self.folder = Path(runs_dir) / "line" / "chain"
        self.station = station
        self.path = self.folder / f"{_safe(station)}.json"

    @contextlib.contextmanager
    def held(self) -> Iterator[Chain]:
        self.folder.mkdir(parents=True, exist_ok=True)
        with open(self.path.with_suffix(".lock"), "a+") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)
            try:
                yield self
            finally:
                fcntl.flock(lock, fcntl.LOCK_UN)

    def head(self) -> tuple[int, str | None]:
        try:
            h = json.loads(self.path.read_text())
            return int(h["index"]), h["sha256"]
        except (OSError, ValueError, KeyError, TypeError):
            return 0, None

    def advance(self, index: int, digest: str) -> None:
        tmp = self.path.with_suffix(".json.tmp")
        tmp.write_text(json.dumps({"station": self.station, "index": index, "sha256": digest}))
        tmp.replace(self.path)


def seal(record: dict[str, Any], chain: Chain, signer: Signer | None, db: Any = None) -> None:
    """Link the record after its station's chain head and sign its hash (the caller holds the chain).
    The head is the later of the runs dir's and the line database's (a runs dir lost or another
    one used by the same station continues the station's chain)."""
    index, prev = chain.head()
    if db is not None and hasattr(db, "chain_head"):
        try:
            db_index, db_prev = db.chain_head(chain.station)
        except Exception:  # noqa: BLE001 - the database down: the runs dir's head
            db_index, db_prev = 0, None
        if db_index > index:
            index, prev = db_index, db_prev
    record["chain"] = {"station": chain.station, "index": index + 1, "prev_sha256": prev}
    digest = record_hash(record)
    record["integrity"] = {"sha256": digest, "algorithm": ALGORITHM if signer else None,
                           "public_key": signer.public_hex if signer else None,
                           "key_id": signer.key_id if signer else None,
                           "signature": signer.sign(digest) if signer else None}


# --- checks --------------------------------------------------------------------------------------
def signature_problem(record: dict[str, Any], trusted: set[str] | None = None) -> str | None:
    """Why the record's hash or signature does not hold (None: it holds); `trusted` public keys
    (hex), when given, are the only keys accepted."""
    from cryptography.exceptions import InvalidSignature
    from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PublicKey

    integ = record.get("integrity")
    if not isinstance(integ, dict) or not integ.get("sha256"):
        return "it carries no hash (written before records were sealed, or the field was removed)"
    if record_hash(record) != integ["sha256"]:
        return "its content does not match its hash (edited after it was written)"
    if not integ.get("signature"):
        return "it is not signed (its station names no line_key)"
    try:
        key = Ed25519PublicKey.from_public_bytes(bytes.fromhex(integ["public_key"]))
        key.verify(bytes.fromhex(integ["signature"]), bytes.fromhex(integ["sha256"]))
    except (InvalidSignature, ValueError, TypeError):
        return "its signature does not match its hash"
    if trusted is not None and integ["public_key"] not in trusted:
        return f"it is signed by key {integ.get('key_id')}, not a trusted key"
    return None


def raw_file_problems(record: dict[str, Any]) -> list[str]:
    """Each run's raw file against the SHA-256 the record holds."""
    from .record import sha256_of

    out = []
    for r in record.get("runs") or ():
        path, want = r.get("raw_file"), r.get("sha256")
        if not path:
            continue
        if not Path(path).is_file():
            out.append(f"raw file {path} is missing")
        elif sha256_of(path) != want:
            out.append(f"raw file {path} does not match its SHA-256 in the record")
    return out


def rejudge_problems(record: dict[str, Any]) -> list[str]:
    """The record's verdicts judged again against the limits file it names (its hash checked
    first): each limited measurement's outcome and limits, and the unit's outcome."""
    from .limits import load_limits
    from .record import sha256_of
    from .verdict import ABORTED, ERROR, FAIL, MARGINAL, PASS, judge, worst

    path = record.get("limits_file")
    if not path or not Path(path).is_file():
        return [f"its limits file {path!r} is not there to judge it again"]
    if record.get("limits_sha256") and sha256_of(path) != record["limits_sha256"]:
        return [f"its limits file {path} has changed since the record was written"]
    limits = load_limits(path)
    out = []
    for m in record.get("measurements") or ():
        lim = next((x for x in limits.limits if x.name == m.get("name") and x.procedure in (None, m.get("procedure"))),
                   None)
        if lim is None:
            if m.get("rule"):
                out.append(f"{m.get('name')}: judged by a limit its limits file does not hold")
            continue
        if (m.get("limits") or {}) != {"low": lim.low, "high": lim.high}:
            out.append(f"{m.get('name')}: limits {m.get('limits')} are not the file's ({lim.low}..{lim.high})")
            continue
        if m.get("outcome") in (PASS, FAIL, MARGINAL):
            iv = m.get("interval")
            interval = None if iv is None else tuple(float("nan") if x is None else x for x in iv)
            v = judge(m.get("value"), interval, lim)
            if v.outcome != m["outcome"]:
                out.append(f"{m.get('name')}={m.get('value')}: recorded {m['outcome']}, judged {v.outcome}")
        elif m.get("value") is not None:
            out.append(f"{m.get('name')}: recorded {m.get('outcome')} with a value {m.get('value')}")
    decided = [m["outcome"] for m in record.get("measurements") or () if m.get("rule")] + [
        r["outcome"] for r in record.get("runs") or () if r.get("outcome") in (ERROR, ABORTED)]
    if record.get("abort_reason"):
        decided.append(ABORTED)
    if record.get("outcome") != worst(decided):
        out.append(f"the unit's outcome is recorded {record.get('outcome')}, its measurements give {worst(decided)}")
    return out
