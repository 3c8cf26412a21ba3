"""File settings (:data:`~rehabkit.models.strict.FilePath`) mean the file beside the scenario file that writes them.

A base file (``extends:``) that names ``file: arm4.urdf`` means the URDF beside the base, wherever the scenario
extending it lives: such a relative path is made absolute from the folder of the file it was written in (its
value's mark). The scenario's own relative paths stay as written (its run's snapshot keeps them portable); a URI
(``package://``, ``file://``) is left as it is, for the plugin to resolve.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from pydantic import BaseModel

from rehabkit.core.scenario.source import Source
from rehabkit.models.strict import FILE_SETTING, marked_settings


def _set_at(data: Any, loc: tuple, value: Any) -> None:
    for key in loc[:-1]:
        data = data[key]
    data[loc[-1]] = value


def anchor_file_settings(src: Source, scenario: BaseModel, path: Path) -> bool:
    """File settings (:data:`~rehabkit.models.strict.FilePath`) written relative in another file than the scenario
    (an ``extends:`` base, a profile) made absolute from that file's folder; whether any was."""
    here, changed = path.resolve(), False
    for loc, value in marked_settings(scenario, FILE_SETTING):
        mark = src.value_marks.get(loc)
        written = Path(mark.file).resolve() if mark is not None and not mark.file.startswith("<") else here
        if written != here and "://" not in value and not Path(value).expanduser().is_absolute():
            _set_at(src.data, loc, str((written.parent / value).resolve()))
            changed = True
    return changed
