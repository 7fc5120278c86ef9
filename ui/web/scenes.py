"""What a page may open: the bundled scenes by name, and TOML files its user uploads.

No path from the client reaches the file system: a page names a bundled scene (one of
:func:`bundled`, looked up in the repository's ``scenes/`` folder) or sends a file's bytes,
which :func:`save_upload` checks (size, UTF-8, TOML, no file references) and writes into the
session's own folder before the core loads it. Every refusal is one line (:class:`UploadError`,
or the core's ``SceneError``), the same message the command line prints after
``psurf: error:``.
"""

from __future__ import annotations

import os
import tomllib

from psurf_core.estimators import parse_estimator

#: The repository's bundled scenes.
SCENES_DIR = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(
    os.path.abspath(__file__)))), "scenes")
#: Largest upload accepted (bytes): a scene is a few hundred bytes of TOML.
MAX_UPLOAD = 64 * 1024
#: Keys whose values are file paths (mesh lights and occluders): refused in uploads.
FILE_KEYS = ("mesh",)


class UploadError(ValueError):
    """An upload that is refused before the core sees it (one line)."""


def bundled() -> list[str]:
    """Names (``area.toml``, ...) of the bundled scenes, sorted."""
    return sorted(f for f in os.listdir(SCENES_DIR) if f.endswith(".toml"))


def bundled_path(name: str) -> str:
    """The file of bundled scene ``name``; ``UploadError`` for any other name."""
    if name not in bundled():
        raise UploadError(f"no bundled scene named {name!r} (one of: {', '.join(bundled())})")
    return os.path.join(SCENES_DIR, name)


def _file_refs(table, where: str = "") -> list[str]:
    """Dotted keys of ``table`` (nested dicts and lists) naming a file."""
    out = []
    items = table.items() if isinstance(table, dict) else enumerate(table)
    for k, v in items:
        key = f"{where}.{k}" if where else str(k)
        if isinstance(v, (dict, list)):
            out += _file_refs(v, key)
        elif k in FILE_KEYS:
            out.append(key)
    return out


def check_upload(name: str, content: bytes) -> str:
    """The text of an uploaded scene file, or ``UploadError`` saying what is wrong.

    Parameters
    ----------
    name : str
        The file name the browser reports (shown in messages only, never used as a path).
    content : bytes
        The file's bytes.
    """
    label = os.path.basename(str(name)) or "upload"
    if not label.endswith(".toml"):
        raise UploadError(f"{label}: a scene is a .toml file")
    if len(content) > MAX_UPLOAD:
        raise UploadError(f"{label}: {len(content)} bytes, more than the {MAX_UPLOAD // 1024} "
                          f"KiB an uploaded scene may have")
    try:
        text = bytes(content).decode("utf-8")
    except UnicodeDecodeError:
        raise UploadError(f"{label}: not UTF-8 text") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError:
        return text  # the core's loader says what is wrong, as on the command line
    refs = _file_refs(data)
    if refs:
        raise UploadError(f"{label}: {refs[0]}: an uploaded scene cannot reference files "
                          f"(meshes); open a bundled mesh scene instead")
    return text


def save_upload(name: str, content: bytes, folder: str, index: int) -> str:
    """Check an upload (:func:`check_upload`) and write it as ``folder/upload-<index>.toml``;
    returns that path (the core then loads it and may still raise ``SceneError``)."""
    text = check_upload(name, content)
    os.makedirs(folder, exist_ok=True)
    path = os.path.join(folder, f"upload-{int(index)}.toml")
    with open(path, "w", encoding="utf-8") as f:
        f.write(text)
    return path


def parse_specs(text: str, scene) -> list[str]:
    """``A,B`` checked for ``scene`` (the first, inspected, needs photons); ``ValueError``
    with one line otherwise (the message ``serve --estimators`` gives)."""
    specs = [e.strip() for e in str(text).split(",")]
    if not specs or any(not e for e in specs):
        raise ValueError(f"estimators must be specs A,B, got {text!r}")
    for i, e in enumerate(specs):
        try:
            est = parse_estimator(e, scene)
        except (ValueError, KeyError, ModuleNotFoundError) as ex:
            raise ValueError(f"estimator {e!r}: {' '.join(str(ex).split())}") from None
        if i == 0 and est.reference:
            raise ValueError("the first estimator is the one the stages inspect: it must be "
                             f"a photon estimator, not {e!r}")
    return specs
