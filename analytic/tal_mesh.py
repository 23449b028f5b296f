"""A hidden OBJ mesh of a tal configuration as one planar rectangle, or a one-line refusal.

tal (y-tal) hands an OBJ file to Mitsuba, which renders each face with
the face's own orientation (its vertices counter-clockwise about the lit
normal; Mitsuba's ``diffuse`` is one-sided). The exact model holds a
Lambertian rectangle: a mesh is accepted when its faces are coplanar, all
face the same side, and together cover a rectangle exactly once.

Why the test below is exact: with every face oriented the same way, the
number of faces over a point of the plane is the winding number of the
mesh's boundary (the directed edges that no face's reverse edge cancels)
about it. When that boundary runs once counter-clockwise along the convex
hull's sides, every point of the hull is covered exactly once, and the
union of the faces is the hull; the hull must then be a rectangle. A
non-rectangular polygon (tal's ``Z.obj``) is refused, as is a mesh with a
T-junction (its boundary keeps an inner edge), a fold or a hole.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .errors import SceneError

__all__ = ["read_obj", "planar_rectangle", "MAX_OBJ_BYTES"]

#: Largest OBJ file read, bytes: a rectangle needs a few lines.
MAX_OBJ_BYTES = 1 << 24

#: Relative tolerance of coplanarity, right angles and coverage (OBJ files hold 6 decimals).
_TOLERANCE = 1e-5


def read_obj(path: Path, key: str) -> tuple[np.ndarray, list[list[int]], np.ndarray | None]:
    """The vertices ``(V, 3)``, faces (0-based vertex indices) and per-face normals (``vn``) of an OBJ file.

    Only ``v``, ``vn``, ``vt`` and ``f`` records are read (``o``, ``g``, ``s``,
    ``mtllib``, ``usemtl`` and comments are skipped, as Mitsuba does); the
    face normal is the first vertex's ``vn`` when the face names one.

    Raises
    ------
    SceneError
        Under ``key``: unreadable, too large, a malformed record or an index out of range.
    """
    try:
        if path.stat().st_size > MAX_OBJ_BYTES:
            raise SceneError(key, f"{path}: larger than {MAX_OBJ_BYTES >> 20} MiB; a planar hidden rectangle "
                                  f"needs a few lines")
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError as error:
        raise SceneError(key, f"cannot read {path} ({error.strerror})") from None
    vertices, normals, faces, face_normals = [], [], [], []
    for number, line in enumerate(text.splitlines(), start=1):
        fields = line.split("#", 1)[0].split()
        if not fields or fields[0] not in ("v", "vn", "f"):
            continue
        try:
            if fields[0] in ("v", "vn"):
                (vertices if fields[0] == "v" else normals).append([float(x) for x in fields[1:4]])
                if len(fields) < 4:
                    raise ValueError
                continue
            corners = [field.split("/") for field in fields[1:]]
            indices = [int(c[0]) for c in corners]
            faces.append([i - 1 if i > 0 else len(vertices) + i for i in indices])
            names = [c[2] for c in corners if len(c) > 2 and c[2]]
            face_normals.append(int(names[0]) - 1 if names else None)
            if len(indices) < 3:
                raise ValueError
        except ValueError:
            raise SceneError(key, f"{path}, line {number}: not a valid OBJ {fields[0]} record "
                                  f"({line.strip()[:60]!r})") from None
    if not faces:
        raise SceneError(key, f"{path}: no faces (f records); tal renders nothing of it")
    vertices = np.array(vertices, dtype=np.float64).reshape(-1, 3)
    if any(i < 0 or i >= len(vertices) for face in faces for i in face) or \
            any(n is not None and not 0 <= n < len(normals) for n in face_normals):
        raise SceneError(key, f"{path}: a face names a vertex or normal that the file does not define")
    stated = None
    if any(n is not None for n in face_normals):
        table = np.array(normals, dtype=np.float64).reshape(-1, 3)
        stated = np.array([table[n] if n is not None else np.full(3, np.nan) for n in face_normals])
    return vertices, faces, stated


def _face_normal(points: np.ndarray) -> np.ndarray:
    """Twice the vector area of a (planar) polygon: its normal by the right-hand rule, its area's length."""
    total = np.zeros(3)
    for i in range(1, len(points) - 1):
        total += np.cross(points[i] - points[0], points[i + 1] - points[0])
    return total


def _hull(points: np.ndarray) -> np.ndarray:
    """Indices of the 2-D convex hull, counter-clockwise, collinear points dropped (Andrew's monotone chain)."""
    order = sorted(range(len(points)), key=lambda i: (points[i, 0], points[i, 1]))
    scale = float(np.ptp(points, axis=0).max()) or 1.0

    def turn(o, a, b):
        return ((points[a, 0] - points[o, 0]) * (points[b, 1] - points[o, 1])
                - (points[a, 1] - points[o, 1]) * (points[b, 0] - points[o, 0]))

    def chain(indices):
        kept = []
        for i in indices:
            while len(kept) >= 2 and turn(kept[-2], kept[-1], i) <= _TOLERANCE * scale**2:
                kept.pop()
            kept.append(i)
        return kept
    lower, upper = chain(order), chain(order[::-1])
    return np.array(lower[:-1] + upper[:-1])


def planar_rectangle(vertices: np.ndarray, faces: list[list[int]], stated_normals: np.ndarray | None,
                     key: str, shown: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The rectangle that a mesh's faces cover: ``(corner, u, v)`` with u x v along the lit normal.

    Parameters
    ----------
    vertices : numpy.ndarray
        ``(V, 3)`` world positions (the geometry's transform applied), metres.
    faces : list of list of int
        Each face's vertex indices, counter-clockwise about its lit side.
    stated_normals : numpy.ndarray or None
        ``(F, 3)`` the faces' ``vn`` in world space (NaN where none), to
        check that they agree with the winding.
    key, shown : str
        The configuration key and the file's name, for messages.

    Raises
    ------
    SceneError
        Faces that are not coplanar, that face both ways, that do not cover
        a rectangle exactly once (a Z, a T-junction, a hole), or whose
        stated normals contradict their winding.
    """
    used = sorted({i for face in faces for i in face})
    points = vertices[used]
    size = float(np.ptp(points, axis=0).max())
    if not size > 0:
        raise SceneError(key, f"{shown}: its faces have no extent")
    areas = np.array([_face_normal(vertices[face]) for face in faces])
    lengths = np.linalg.norm(areas, axis=1)
    if np.any(lengths <= _TOLERANCE * size**2):
        raise SceneError(key, f"{shown}: a face of zero area (degenerate); remove it")
    normal = areas.sum(axis=0)
    normal /= np.linalg.norm(normal)
    if np.any(areas @ normal <= (1 - _TOLERANCE) * lengths):
        raise SceneError(key, f"{shown}: its faces are not coplanar and facing one side; the model's hidden "
                              f"surface is one planar Lambertian rectangle")
    centre = points.mean(axis=0)
    if np.max(np.abs((points - centre) @ normal)) > _TOLERANCE * size:
        raise SceneError(key, f"{shown}: its vertices do not lie in one plane; the model's hidden surface is one "
                              f"planar Lambertian rectangle")
    if stated_normals is not None:
        given = ~np.isnan(stated_normals[:, 0])
        if np.any(stated_normals[given] @ normal <= 0):
            raise SceneError(key, f"{shown}: a face's vn normal points against its winding; Mitsuba would shade "
                                  f"it from the other side: make the vn agree with the vertex order")
    # plane coordinates, (e1, e2, normal) right-handed
    e1 = points[np.argmax(np.linalg.norm(points - points[0], axis=1))] - points[0]
    e1 -= (e1 @ normal) * normal
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(normal, e1)
    flat = np.column_stack([(vertices - centre) @ e1, (vertices - centre) @ e2])
    hull = [used[i] for i in _hull(flat[used])]
    corners = flat[hull]
    if len(corners) != 4:
        raise SceneError(key, f"{shown}: its faces cover a polygon of {len(corners)} corners, not a rectangle; "
                              f"the model holds a planar rectangle (other polygons are refused)")
    sides = np.roll(corners, -1, axis=0) - corners
    lengths4 = np.linalg.norm(sides, axis=1)
    cosines = np.abs(np.sum(sides * np.roll(sides, -1, axis=0), axis=1)) / (lengths4 * np.roll(lengths4, -1))
    if np.any(cosines > _TOLERANCE):
        raise SceneError(key, f"{shown}: its faces cover a quadrilateral that is not a rectangle (corner angles "
                              f"off 90 degrees); the model holds a planar rectangle")
    _covers_once(flat, faces, corners, sides, lengths4, key, shown)
    corner = centre + corners[0, 0] * e1 + corners[0, 1] * e2
    u = sides[0, 0] * e1 + sides[0, 1] * e2
    v = -(sides[3, 0] * e1 + sides[3, 1] * e2)
    return corner, u, v


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The z component of 2-D cross products (NumPy 2 retired np.cross of 2-vectors)."""
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def _covers_once(flat, faces, corners, sides, lengths, key: str, shown: str) -> None:
    """Refuse unless the faces' uncancelled edges run once, counter-clockwise, along the rectangle's sides."""
    edges: dict[tuple[int, int], int] = {}
    for face in faces:
        for a, b in zip(face, face[1:] + face[:1]):
            if (b, a) in edges:
                edges[(b, a)] -= 1
                if not edges[(b, a)]:
                    del edges[(b, a)]
            else:
                edges[(a, b)] = edges.get((a, b), 0) + 1
    scale = float(lengths.max())
    covered = np.zeros(4)
    for (a, b), count in edges.items():
        step = flat[b] - flat[a]
        # which side holds the edge, running its way
        offsets = _cross(sides, flat[a] - corners) / lengths
        along = _cross(sides, flat[b] - corners) / lengths
        side = np.flatnonzero((np.abs(offsets) <= _TOLERANCE * scale) & (np.abs(along) <= _TOLERANCE * scale)
                              & (sides @ step > 0))
        if count != 1 or len(side) != 1:
            raise SceneError(key, f"{shown}: its faces do not cover one rectangle exactly once (an inner edge "
                                  f"left open: a hole, an overlap or a T-junction); the model holds a planar "
                                  f"rectangle")
        covered[side[0]] += np.linalg.norm(step)
    if np.any(np.abs(covered - lengths) > _TOLERANCE * scale):
        raise SceneError(key, f"{shown}: its faces do not cover one rectangle exactly once; the model holds a "
                              f"planar rectangle")
