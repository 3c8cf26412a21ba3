"""Writing outputs whole or not at all; reading YAML data files fast."""

from __future__ import annotations

import json
import os
import re
import tempfile
from pathlib import Path
from typing import Any

import yaml

_BASE_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)  # libyaml where installed: ~10x the pure-Python parser

# the process's umask, read once: reading it means setting it, which other threads writing files would meet
_UMASK = os.umask(0)
os.umask(_UMASK)


class YAML_LOADER(_BASE_LOADER):  # noqa: N801 (a loader class, named as the constant it replaced)
    """PyYAML's safe loader reading numbers as YAML 1.2 does (and editors' YAML, e.g. check-jsonschema's): ``1e-6``
    is a number, not the text PyYAML's YAML 1.1 makes of an exponent without a decimal point."""


YAML_LOADER.add_implicit_resolver(
    "tag:yaml.org,2002:float", re.compile(r"^[-+]?[0-9][0-9_]*(?:\.[0-9_]*)?[eE][-+]?[0-9]+$"), list("-+0123456789"))


def load_yaml(text: str) -> Any:
    """``yaml.safe_load`` by libyaml (a robot's joint table: ~1 ms instead of ~10), numbers as YAML 1.2 reads them:
    a data file, or one value as a scenario file would read it (a ``--set`` or ``--grid`` value)."""
    return yaml.load(text, Loader=YAML_LOADER)


def atomic_write_text(path: Path, text: str, private: bool = False) -> None:
    """Write ``text`` (UTF-8) to a temporary file beside ``path``, then rename it into place (``private``: readable
    by its owner only from the start, e.g. a key)."""
    atomic_write_bytes(path, text.encode(), private)


def atomic_write_bytes(path: Path, data: bytes, private: bool = False) -> None:
    """Write ``data`` to a temporary file beside ``path``, synced, then rename it into place (``private``: readable
    by its owner only from the start)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")  # (created 0600)
    if not private:  # outputs are ordinary files
        os.fchmod(fd, 0o666 & ~_UMASK)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def atomic_write_json(path: Path, data: Any) -> None:
    """JSON with sorted keys and NaN written as null."""
    atomic_write_text(path, json.dumps(_clean(data), indent=2, sort_keys=False) + "\n")


def _clean(x: Any) -> Any:
    if isinstance(x, dict):
        return {str(k): _clean(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_clean(v) for v in x]
    if hasattr(x, "item") and getattr(x, "ndim", 1) == 0:
        x = x.item()
    if isinstance(x, float) and x != x:
        return None
    return x
