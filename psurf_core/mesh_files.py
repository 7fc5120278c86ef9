"""Triangle counts of a scene's mesh files, read without loading the meshes.

:func:`psurf_core.scene_io.load_scene` hands mesh files to trimesh, which needs about
:data:`psurf_core.budget.TRIANGLE_LOAD_BYTES` per triangle while it loads; a mesh too large
for the memory must be refused before that. :func:`scene_mesh_files` lists the mesh files a
scene file names (resolved as the loader resolves them) and :func:`triangle_count` estimates
a file's triangles from its header (binary STL, PLY, OFF) or by counting its face records
(OBJ, ASCII STL) in a streaming read. Anything unreadable or unknown gives ``None``: the
loader then reports the problem, and the triangles are counted exactly once loaded.
"""

from __future__ import annotations

import os
import tomllib

__all__ = ["scene_mesh_files", "triangle_count"]

#: Bytes read at a time when counting face records.
_BLOCK = 1 << 22


def scene_mesh_files(scene_path: str | os.PathLike) -> list[tuple[str, str]]:
    """``(key, path)`` of every mesh the scene file names (``lights[0].mesh``, ...), with
    paths relative to the scene file's folder as the loader takes them; ``[]`` when the file
    cannot be read (the loader says why)."""
    try:
        with open(scene_path, "rb") as f:
            data = tomllib.load(f)
    except (OSError, ValueError):
        return []
    base = os.path.dirname(os.path.abspath(scene_path))
    out = []
    for section in ("lights", "occluders"):
        entries = data.get(section, [])
        if not isinstance(entries, list):
            continue
        for i, t in enumerate(entries):
            if isinstance(t, dict) and t.get("type") == "mesh" and isinstance(t.get("mesh"), str):
                out.append((f"{section}[{i}].mesh",
                            os.path.normpath(os.path.join(base, t["mesh"]))))
    return out


def triangle_count(path: str) -> int | None:
    """Triangles in the mesh file ``path`` (polygons count as their fan triangles where the
    header says; OBJ faces count once each), or ``None`` when unknown."""
    try:
        size = os.path.getsize(path)
        ext = os.path.splitext(path)[1].lower()
        with open(path, "rb") as f:
            head = f.read(512)
            if ext == ".stl":
                return _stl(f, head, size)
            if ext == ".ply":
                return _ply(head)
            if ext == ".off":
                return _off(head)
            if ext == ".obj":
                return _count_lines(f, (b"f ", b"f\t"))
    except OSError:
        return None
    return None


def _stl(f, head: bytes, size: int) -> int | None:
    if len(head) >= 84:
        n = int.from_bytes(head[80:84], "little")
        if 84 + 50 * n == size:  # binary STL
            return n
    if head.lstrip().lower().startswith(b"solid"):
        return _count_lines(f, (b"facet",))
    return (size - 84) // 50 if size > 84 else None


def _ply(head: bytes) -> int | None:
    for line in head.split(b"\n"):
        words = line.split()
        if len(words) == 3 and words[0] == b"element" and words[1] == b"face":
            try:
                return int(words[2])
            except ValueError:
                return None
        if line.strip() == b"end_header":
            break
    return None


def _off(head: bytes) -> int | None:
    lines = [ln.split(b"#")[0].strip() for ln in head.split(b"\n")]
    lines = [ln for ln in lines if ln]
    if not lines or not lines[0].upper().endswith(b"OFF"):
        return None
    counts = lines[0][3:].split() if len(lines[0]) > 3 else (lines[1].split() if len(lines) > 1
                                                               else [])
    try:
        return int(counts[1])
    except (IndexError, ValueError):
        return None


def _count_lines(f, starts: tuple[bytes, ...]) -> int:
    """Lines whose first non-blank characters are one of ``starts`` (streaming, from 0)."""
    f.seek(0)
    n = 0
    tail = b"\n"
    while True:
        block = f.read(_BLOCK)
        if not block:
            break
        text = tail + block
        cut = text.rfind(b"\n")
        if cut <= 0:
            tail = text[-(1 << 16):] if len(text) > 1 << 16 else text  # one long line
            continue
        whole, tail = text[:cut + 1], text[cut:]
        for s in starts:
            n += whole.count(b"\n" + s) + whole.count(b"\n " + s) + whole.count(b"\n\t" + s)
    return n
