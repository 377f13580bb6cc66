"""The tetrahedral mesh of the rod (the paper's Section V-C), generated from code.

The paper's soft object is a 1.55 m cylinder of radius 0.025 m meshed with 200 nodes,
392 tetrahedra, 789 edges and 396 surface triangles. We build the same structure:

* 33 hexagonal rings of 6 surface nodes; ring ``k`` lies at height ``k * length / 32``;
* the centre of each end face: node 0 at the bottom, node 1 at the top;
* each hexagon is split into 4 triangles by 3 diagonals, so every inner layer between two
  rings is 4 triangular prisms, each cut into 3 tetrahedra (12 per layer, 30 layers);
* the two end layers (rings 0-1 and 31-32) are cones from their end-face centre: one
  tetrahedron from the centre to each of the layer's 12 side triangles and to the 4 triangles
  of the far hexagon (16 per end layer). The end faces are then fans of 6 triangles around
  the centre, flat like the real rod's ends.

That gives 30 x 12 + 2 x 16 = 392 tetrahedra and, with the end fans, 396 surface triangles
and 789 edges, the counts of the paper's Gmsh mesh.

Which diagonal cuts each side quad does not change these counts, but it does change the
rod's stiffness pattern. The shipped mesh (``cuts="course"``) repeats one cut pattern in
every layer. The authors' Gmsh file cuts each quad through the lowest-numbered of its nodes
too, but Gmsh numbered every odd ring after both its neighbours, so each layer is the mirror
image of the next (``cuts="mirrored"`` does that; within a ring Gmsh's corner order varies
with no pattern, so 182 of their 392 tetrahedra are those of ``"mirrored"``, 134 of
``"course"``). Closer by count is not closer in behaviour: swept as the authors did, the
mirrored rod buckles another way, 58.7 mm from their small sweep against 4.9 mm for the
default (benchmarks/results/mesh_vs_authors.md), so the default stays.

Node numbering: ``0`` bottom centre, ``1`` top centre, then ring ``k``, corner ``j`` (at
angle ``j * 60°`` from +x) is node ``2 + 6 k + j``. The paper selects nodes on the +x surface
line (corner 0), named here by ring: :func:`node_of_ring`.

The file written is the ASCII legacy VTK (``UNSTRUCTURED_GRID`` of tetrahedra, cell type 10)
that ``pybullet.loadSoftBody`` reads.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

N_RINGS = 33
RING_CORNERS = 6

# The 3 diagonals that split a hexagon (corners 0..5) into 4 triangles: a central triangle
# (0, 2, 4) and three "ears". Any triangulation would do; this one is symmetric.
HEXAGON_TRIANGLES = ((0, 1, 2), (2, 3, 4), (4, 5, 0), (0, 2, 4))


# The paper's selected nodes, all on the +x surface line, named by ring (FACTS.md).
SELECTED_RINGS: dict[int, tuple[int, ...]] = {
    2: (26, 15),
    4: (26, 23, 18, 15),
    6: (26, 23, 18, 15, 8, 29),
}


def selected_nodes(n_nodes: int) -> tuple[int, ...]:
    """Mesh node indices of the paper's ``n_nodes`` selected nodes (2, 4 or 6)."""
    if n_nodes not in SELECTED_RINGS:
        raise ValueError(f"n_nodes must be one of {sorted(SELECTED_RINGS)}, got {n_nodes!r}")
    return tuple(node_of_ring(k) for k in SELECTED_RINGS[n_nodes])


def node_of_ring(ring: int, corner: int = 0) -> int:
    """Index of the surface node of ``ring`` (0..32) at ``corner`` (0..5, 0 is the +x side)."""
    if not 0 <= ring < N_RINGS:
        raise ValueError(f"ring must be in 0..{N_RINGS - 1}, got {ring}")
    if not 0 <= corner < RING_CORNERS:
        raise ValueError(f"corner must be in 0..{RING_CORNERS - 1}, got {corner}")
    return 2 + RING_CORNERS * ring + corner


@dataclass(frozen=True)
class TetMesh:
    """A tetrahedral mesh.

    Attributes:
        points: (N, 3) float64 node positions in metres, rod axis along +z from z = 0.
        tets: (T, 4) int64 node indices, each tetrahedron positively oriented
            (``det[p1 - p0, p2 - p0, p3 - p0] > 0``).
    """

    points: np.ndarray
    tets: np.ndarray

    @property
    def edges(self) -> np.ndarray:
        """(E, 2) unique undirected edges of all tetrahedra, sorted."""
        pairs = [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)]
        e = np.concatenate([self.tets[:, list(pair)] for pair in pairs])
        return np.unique(np.sort(e, axis=1), axis=0)

    @property
    def surface_triangles(self) -> np.ndarray:
        """(F, 3) faces that belong to exactly one tetrahedron (the boundary)."""
        faces = np.concatenate(
            [self.tets[:, [1, 2, 3]], self.tets[:, [0, 2, 3]],
             self.tets[:, [0, 1, 3]], self.tets[:, [0, 1, 2]]]
        )
        keys, counts = np.unique(np.sort(faces, axis=1), axis=0, return_counts=True)
        return keys[counts == 1]

    def signed_volumes(self) -> np.ndarray:
        """(T,) signed volume of every tetrahedron (positive when correctly oriented)."""
        p = self.points[self.tets]
        return np.linalg.det(np.stack([p[:, 1] - p[:, 0], p[:, 2] - p[:, 0],
                                       p[:, 3] - p[:, 0]], axis=1)) / 6.0


def _split_prism(bottom: tuple[int, int, int], top: tuple[int, int, int],
                 rank: np.ndarray) -> list[tuple]:
    """Cut a triangular prism into 3 tetrahedra, consistently with its neighbours.

    Each quadrilateral side face is cut along the diagonal through its lowest-ranked node
    (``rank``: (N,) int, one distinct rank per node). Two prisms sharing a face then cut it the
    same way, so the mesh is conforming, and the three cuts of one prism never form a cycle,
    so the split always exists.
    """
    ids = list(bottom) + list(top)  # ids[i + 3] sits above ids[i]
    first = int(np.argmin(rank[ids]))
    # Relabel the prism so that its lowest-ranked node is local corner 0 of the bottom triangle.
    base = first % 3
    order = [base, (base + 1) % 3, (base + 2) % 3]
    if first >= 3:  # the lowest-ranked node is on top: flip the prism upside down
        b = [ids[i + 3] for i in order]
        t = [ids[i] for i in order]
    else:
        b = [ids[i] for i in order]
        t = [ids[i + 3] for i in order]
    v0, v1, v2 = b
    w0, w1, w2 = t
    # Both faces touching v0 are cut through v0: the first tetrahedron is v0 + top triangle.
    tets = [(v0, w0, w1, w2)]
    # The remaining pyramid has apex v0 over the quad (v1, v2, w2, w1).
    if min(rank[v1], rank[w2]) < min(rank[v2], rank[w1]):  # diagonal v1-w2
        tets += [(v0, v1, v2, w2), (v0, v1, w2, w1)]
    else:  # diagonal v2-w1
        tets += [(v0, v1, v2, w1), (v0, v2, w2, w1)]
    return tets


def _cut_ranks(cuts: str) -> np.ndarray:
    """(200,) rank of every node for the "diagonal through the lowest rank" rule.

    ``"course"``: the node index, ring after ring, so every layer is cut the same way.
    ``"mirrored"``: all even rings rank before all odd rings, so every layer's cuts go through
    its even ring and each layer is the mirror image of its neighbour across their shared ring.
    The authors' Gmsh file follows this rule (every odd ring is numbered after both its
    neighbours), though within a ring Gmsh's corner order varies where ours does not.
    """
    index = np.arange(2 + RING_CORNERS * N_RINGS)
    if cuts == "course":
        return index
    if cuts == "mirrored":
        ring = np.maximum(index - 2, 0) // RING_CORNERS
        odd = (index >= 2) & (ring % 2 == 1)
        return index + odd * len(index)  # odd rings after every even ring, order kept
    raise ValueError(f"cuts must be 'course' or 'mirrored', got {cuts!r}")


def make_rod_mesh(length: float = 1.55, radius: float = 0.025, cuts: str = "course") -> TetMesh:
    """Build the paper's rod: 200 nodes, 392 tetrahedra, 789 edges, 396 surface triangles.

    ``cuts`` chooses which diagonal cuts every side quad (see :func:`_cut_ranks`): ``"course"``
    (the shipped ``data/rod.vtk``) or ``"mirrored"`` (the authors' pattern of cuts).
    """
    if length <= 0 or radius <= 0:
        raise ValueError("length and radius must be positive")
    rank = _cut_ranks(cuts)
    angles = np.arange(RING_CORNERS) * (2 * np.pi / RING_CORNERS)
    points = [(0.0, 0.0, 0.0), (0.0, 0.0, length)]
    for k in range(N_RINGS):
        z = k * length / (N_RINGS - 1)
        points += [(radius * np.cos(a), radius * np.sin(a), z) for a in angles]
    points = np.asarray(points, dtype=np.float64)
    points[np.abs(points) < 1e-15] = 0.0

    tets: list[tuple] = []
    last = N_RINGS - 1
    for k in range(1, last - 1):  # inner layers: prisms
        for tri in HEXAGON_TRIANGLES:
            bottom = tuple(node_of_ring(k, c) for c in tri)
            top = tuple(node_of_ring(k + 1, c) for c in tri)
            tets += _split_prism(bottom, top, rank)
    # End layers: a flat end face cannot hold a tetrahedron (centre and ring are coplanar),
    # so the centre instead sees the whole layer next to it.
    for centre, near, far in ((0, 0, 1), (1, last, last - 1)):
        for j in range(RING_CORNERS):
            a, b = node_of_ring(near, j), node_of_ring(near, (j + 1) % RING_CORNERS)
            c, d = node_of_ring(far, j), node_of_ring(far, (j + 1) % RING_CORNERS)
            # Cut the side quad (a, b, d, c) along the diagonal through its lowest-ranked node.
            if min(rank[a], rank[d]) < min(rank[b], rank[c]):
                tets += [(centre, a, b, d), (centre, a, d, c)]
            else:
                tets += [(centre, a, b, c), (centre, b, d, c)]
        for tri in HEXAGON_TRIANGLES:
            tets.append((centre,) + tuple(node_of_ring(far, c) for c in tri))

    tets = np.asarray(tets, dtype=np.int64)
    mesh = TetMesh(points, tets)
    # Orientation is fixed afterwards rather than reasoned case by case: swapping two nodes
    # flips the sign of the volume.
    negative = mesh.signed_volumes() < 0
    tets[negative] = tets[negative][:, [0, 2, 1, 3]]
    return TetMesh(points, tets)


def write_vtk(mesh: TetMesh, path: str | Path) -> Path:
    """Write ``mesh`` as ASCII legacy VTK (the format ``pybullet.loadSoftBody`` reads)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    lines = [
        "# vtk DataFile Version 2.0",
        "dlo-course rod: 33 hexagonal rings + 2 end centres, generated by dlo_course.mesh",
        "ASCII",
        "DATASET UNSTRUCTURED_GRID",
        f"POINTS {len(mesh.points)} double",
    ]
    lines += [" ".join(repr(float(c)) for c in p) for p in mesh.points]
    lines.append(f"CELLS {len(mesh.tets)} {5 * len(mesh.tets)}")
    lines += ["4 " + " ".join(str(int(i)) for i in t) for t in mesh.tets]
    lines.append(f"CELL_TYPES {len(mesh.tets)}")
    lines += ["10"] * len(mesh.tets)
    # Write then rename, so parallel processes never read a half-written file.
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text("\n".join(lines) + "\n")
    os.replace(tmp, path)
    return path


def read_vtk(path: str | Path) -> TetMesh:
    """Read a tetrahedral ASCII legacy VTK file written by :func:`write_vtk` (or Gmsh)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no mesh file at {path}; run `dlo-course mesh` to create it")
    tokens = path.read_text().split()
    try:
        i = tokens.index("POINTS")
        n = int(tokens[i + 1])
        points = np.array(tokens[i + 3 : i + 3 + 3 * n], dtype=np.float64).reshape(n, 3)
        j = tokens.index("CELLS")
        m = int(tokens[j + 1])
        cells = np.array(tokens[j + 3 : j + 3 + 5 * m], dtype=np.int64).reshape(m, 5)
    except (ValueError, IndexError) as err:
        raise ValueError(f"{path} is not a tetrahedral legacy VTK file: {err}") from err
    if not np.all(cells[:, 0] == 4):
        raise ValueError(f"{path}: every cell must be a tetrahedron (4 nodes)")
    return TetMesh(points, cells[:, 1:])
