"""A hidden OBJ mesh of a tal configuration as a planar polygon on a pixel grid, or a one-line refusal.

tal (y-tal) hands an OBJ file to Mitsuba, which renders each face with
the face's own orientation (its vertices counter-clockwise about the lit
normal; Mitsuba's ``diffuse`` is one-sided). The exact model holds a
Lambertian rectangle imaged as M x M pixels, each pixel a column of A
scaled by its reflectance. A planar polygon is held exactly as its
bounding rectangle with the polygon's indicator image (1 on the pixels it
covers, 0 elsewhere) as the reflectance, when every side of its outline
lies on a line of that rectangle's pixel grid: then each pixel is wholly
in or wholly out, and the columns of the pixels outside are multiplied by
0. A rectangle is the case where the image is all ones; an L or a
notched rectangle whose corners fall on pixel corners is another. Any
other planar polygon (a triangle, a slanted side, a corner between grid
lines) is refused: its pixels would need clipping, which the model does not do.

Why the coverage is exact: with every face (and every triangle of each
face's fan from its first vertex) facing the lit side, the number of faces
over a point of the plane is the winding number, about it, of the mesh's
outline (the directed edges that no face's reverse edge cancels). With the
outline on grid lines that number is constant over each pixel, so its
value at the pixel's centre is the pixel's; a value other than 0 or 1
(overlapping faces) is refused.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from analytic.errors import SceneError
from analytic.values import MAX_LENGTH, MIN_LENGTH, exact

__all__ = ["read_obj", "planar_polygon", "indicator_image", "MAX_OBJ_BYTES"]

#: Largest OBJ file read, bytes: a planar polygon needs a few lines.
MAX_OBJ_BYTES = 1 << 24

#: Relative tolerance of coplanarity, right angles and the pixel grid (OBJ files hold 6 decimals).
_TOLERANCE = 1e-5


def read_obj(path: Path, key: str) -> tuple[np.ndarray, list[list[int]], np.ndarray | None]:
    """The vertices ``(V, 3)``, faces (0-based vertex indices) and per-face normals (``vn``) of an OBJ file.

    Only ``v``, ``vn``, ``vt`` and ``f`` records are read (``o``, ``g``, ``s``,
    ``mtllib``, ``usemtl`` and comments are skipped, as Mitsuba does); the
    face normal is the first vertex's ``vn`` when the face names one.

    Raises
    ------
    SceneError
        Under ``key``: unreadable, too large, a malformed record (a coordinate that is not a
        finite number included) or an index out of range.
    """
    try:
        if path.stat().st_size > MAX_OBJ_BYTES:
            raise SceneError(key, f"{path}: larger than {MAX_OBJ_BYTES >> 20} MiB; a planar hidden polygon "
                                  f"needs a few lines")
        # -sig: a byte-order mark would make the first record "\ufeffv", skipped, and every index off by one
        text = path.read_text(encoding="utf-8-sig", errors="replace")
    except OSError as error:
        raise SceneError(key, f"cannot read {path} ({error.strerror})") from None
    vertices, normals, faces, face_normals = [], [], [], []
    for number, line in enumerate(text.splitlines(), start=1):
        fields = line.split("#", 1)[0].split()
        if not fields or fields[0] not in ("v", "vn", "f"):
            continue
        try:
            if fields[0] in ("v", "vn"):
                values = [float(x) for x in fields[1:4]]
                if len(fields) < 4 or not all(map(math.isfinite, values)):     # "inf", "nan", "1e400"
                    raise ValueError
                (vertices if fields[0] == "v" else normals).append(values)
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


def _refuse_plane(key: str, shown: str, what: str) -> SceneError:
    return SceneError(key, f"{shown}: {what}; the model's hidden surface is one planar Lambertian polygon")


def planar_polygon(vertices: np.ndarray, faces: list[list[int]], stated_normals: np.ndarray | None,
                   key: str, shown: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The bounding rectangle of a planar mesh and its outline: ``(corner, u, v, edges)``.

    The rectangle's sides run along the outline's sides (``u`` along its
    longest one), u x v along the lit normal; ``edges`` ``(E, 2, 3)`` holds
    the outline's directed sides in world metres (each face's edges, those
    that a face's reverse edge cancels removed), counter-clockwise about the
    lit normal. :func:`indicator_image` turns them into the pixels covered.

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
        Vertices beyond ±``MAX_LENGTH`` (or not finite), an extent below
        ``MIN_LENGTH``, faces that are not coplanar, that face both ways (a face's fan of
        triangles from its first vertex included), whose stated normals
        contradict their winding, or an outline with a side that is not
        parallel or perpendicular to the others (a triangle, a slanted side).
    """
    used = sorted({i for face in faces for i in face})
    points = vertices[used]
    # a vertex no face names is not rendered: put it on a used one, so that no bound below sees it (the merging
    # of repeated vertices divided its coordinates: 1e308 overflowed, with a RuntimeWarning, on a legal mesh)
    vertices = np.repeat(points[:1], len(vertices), axis=0)
    vertices[used] = points
    far = float(np.max(np.abs(points)))
    if not far <= MAX_LENGTH:           # inf or NaN too (a transform that overflowed): areas would overflow
        raise SceneError(key, f"{shown}: a vertex at {exact(far)} m is beyond the ±{MAX_LENGTH:g} m this tool "
                              f"resolves in float64; scale the mesh down")
    size = float(np.ptp(points, axis=0).max())
    if not size > 0:
        raise SceneError(key, f"{shown}: its faces have no extent")
    if size < MIN_LENGTH:               # its areas (size^2) would underflow toward 0
        raise SceneError(key, f"{shown}: its extent, {size!r} m, is below the smallest length supported, "
                              f"{MIN_LENGTH:g} m; scale the mesh up")
    centre = points.mean(axis=0)
    normal = np.linalg.svd(points - centre, full_matrices=False)[2][-1]
    if np.max(np.abs((points - centre) @ normal)) > _TOLERANCE * size:
        raise _refuse_plane(key, shown, "its vertices do not lie in one plane (a solid or a curved surface)")
    if any(np.linalg.norm(_face_normal(vertices[face])) <= _TOLERANCE * size**2 for face in faces):
        raise SceneError(key, f"{shown}: a face of zero area (degenerate); remove it")
    # every triangle of every face's fan: the pieces a renderer covers, each counted once if it faces the lit side
    fans = np.array([np.cross(vertices[face[i]] - vertices[face[0]], vertices[face[i + 1]] - vertices[face[0]])
                     for face in faces for i in range(1, len(face) - 1)])
    if fans.sum(axis=0) @ normal < 0:
        normal = -normal
    lengths = np.linalg.norm(fans, axis=1)
    if np.any((lengths > _TOLERANCE * size**2) & (fans @ normal <= (1 - _TOLERANCE) * lengths)):
        raise _refuse_plane(key, shown, "its faces do not all face one side (each face's vertices run "
                                        "counter-clockwise about the lit side)")
    if stated_normals is not None:
        given = ~np.isnan(stated_normals[:, 0])
        if np.any(stated_normals[given] @ normal <= 0):
            raise SceneError(key, f"{shown}: a face's vn normal points against its winding; Mitsuba would shade "
                                  f"it from the other side: make the vn agree with the vertex order")
    # vertices at one position are one vertex (exporters such as Blender's repeat them per face)
    _, first, same = np.unique(np.round((vertices - points.min(axis=0)) / (_TOLERANCE * size)), axis=0,
                               return_index=True, return_inverse=True)
    ends = _outline([[int(first[same.ravel()[i]]) for i in face] for face in faces])
    steps = vertices[ends[:, 1]] - vertices[ends[:, 0]]
    e1 = steps[np.argmax(np.linalg.norm(steps, axis=1))]
    e1 = e1 - (e1 @ normal) * normal
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(normal, e1)
    flat = steps @ np.column_stack([e1, e2])
    slanted = np.minimum(np.abs(flat[:, 0]), np.abs(flat[:, 1])) > _TOLERANCE * np.linalg.norm(flat, axis=1)
    if slanted.any():
        i = int(np.argmax(slanted))
        angle = math.degrees(math.atan2(abs(flat[i, 1]), abs(flat[i, 0])))
        raise SceneError(key, f"{shown}: a side of its outline (from {np.round(vertices[ends[i, 0]], 6).tolist()} "
                              f"to {np.round(vertices[ends[i, 1]], 6).tolist()} m) runs at {angle:.4g} degrees to "
                              f"its longest side; the model holds a planar polygon only where its indicator image "
                              f"is exact: sides along the pixel grid of its bounding rectangle (a rectangle, an L, "
                              f"a notched rectangle), not a triangle or a slanted side")
    lo = (points - centre) @ np.column_stack([e1, e2])
    low, high = lo.min(axis=0), lo.max(axis=0)
    corner = centre + low[0] * e1 + low[1] * e2
    return corner, (high[0] - low[0]) * e1, (high[1] - low[1]) * e2, vertices[ends]


def _outline(faces: list[list[int]]) -> np.ndarray:
    """``(E, 2)`` the faces' directed edges that no reverse edge cancels (repeated as often as they remain)."""
    edges: dict[tuple[int, int], int] = {}
    for face in faces:
        for a, b in zip(face, face[1:] + face[:1]):
            if edges.get((b, a), 0) > 0:
                edges[(b, a)] -= 1
            else:
                edges[(a, b)] = edges.get((a, b), 0) + 1
    return np.array([edge for edge, count in edges.items() for _ in range(count)], dtype=np.int64).reshape(-1, 2)


def indicator_image(edges: np.ndarray, corner: np.ndarray, u: np.ndarray, v: np.ndarray, pixels: int,
                    key: str, shown: str, pixels_key: str) -> np.ndarray | None:
    """The M x M image of the pixels a polygon covers (1) and leaves out (0), or None when it covers them all.

    Exact when every side of the outline lies on a line of the rectangle's
    M x M pixel grid: the faces' coverage (the outline's winding number) is
    then constant over each pixel, and a pixel's column of A times 0 or 1 is
    the light of the part of the polygon over it. Row 0 is at v's far end
    (the image convention of :class:`analytic.scenes.relay_wall.RelayWallScene`).

    Raises
    ------
    SceneError
        Under ``key``: a side between grid lines (naming ``pixels_key`` values
        that would fit), or faces that cover a pixel twice.
    """
    coords = np.stack([(edges - corner) @ axis / (axis @ axis) for axis in (u, v)], axis=-1)   # (E, 2, 2) fractions
    vertical = np.abs(coords[:, 1, 0] - coords[:, 0, 0]) <= _TOLERANCE      # along v: u-fraction constant
    lines = np.where(vertical, coords[:, 0, 0], coords[:, 0, 1])

    def on_grid(m: int) -> bool:
        return bool(np.all(np.abs(lines * m - np.round(lines * m)) <= _TOLERANCE * m))

    if not on_grid(pixels):
        fits = [m for m in range(1, 1025) if on_grid(m)][:3]
        hint = f"choose {pixels_key} so that they do (e.g. {', '.join(map(str, fits))}), or" if fits else \
            "no pixel count up to 1024 fits:"
        raise SceneError(key, f"{shown}: its corners do not lie on the {pixels} x {pixels} pixel grid of its "
                              f"bounding rectangle ({np.linalg.norm(u):.6g} x {np.linalg.norm(v):.6g} m), so its "
                              f"indicator image would not be exact; {hint} use a rectangle")
    # winding number at each pixel centre: a ray toward +u crosses the sides along v to its right
    centre_u = (np.arange(pixels) + 0.5) / pixels
    centre_v = (pixels - np.arange(pixels) - 0.5) / pixels            # row 0 at the top
    winding = np.zeros((pixels, pixels), dtype=np.int64)
    for (a, _), (b0, b1) in zip(coords[vertical, 0], coords[vertical][:, :, 1]):
        rows = (np.minimum(b0, b1) < centre_v) & (centre_v < np.maximum(b0, b1))
        winding += np.sign(b1 - b0).astype(np.int64) * (rows[:, None] & (centre_u[None, :] < a))
    if winding.min() < 0 or winding.max() > 1:
        raise SceneError(key, f"{shown}: its faces cover part of the plane {winding.max()} times (they overlap); "
                              f"the model holds each point of the polygon covered once")
    return None if winding.min() == 1 else winding.astype(np.float64)
