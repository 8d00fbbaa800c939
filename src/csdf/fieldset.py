"""Many posed fields queried at once: the field layer of scenes.

A :class:`FieldSet` holds posed :class:`csdf.field.Field` objects (instances) and
answers batched queries with one compiled call: for each point the smallest instance
value (the union's field), which instance gave it, its gradient and whether it is the
exact distance, and collision tests of spheres. A bounding volume hierarchy over the
instances' world boxes (:func:`build_bvh`) keeps the cost of a query close to that of
the few instances near it (:mod:`csdf.backends.nearest_kernels`). Each distinct
(program, parameter values) pair becomes one register tape, shared by its instances.

A model whose shape is a hard union (``a | b | ...``, nested unions flattened) enters
the hierarchy part by part (:func:`union_parts`): the scene's value is the smallest
part value either way, but each part has its own tight box, so a query evaluates the
parts near it instead of the whole model (a point 1 m from a chair runs the leg nearest
to it, not all of the chair). The parts keep the model's contract and instance index.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .bvh import build_bvh
from .cache import memo
from .errors import CsdfError
from .field import Field, field_bounds, numba_available
from .parallel import N_THREADS, executor
from .shapes.palette import COLOR_NODES

__all__ = ["FieldSet", "build_bvh", "cell_depth", "union_parts", "LEAF_SIZE",
           "CELL_MIN_INSTRUCTIONS", "MAX_PARTS"]

#: instances per BVH leaf
LEAF_SIZE = 2
#: below this many points a query runs on the calling thread alone
SERIAL_BELOW = 4096
#: models of at least this many instructions keep tapes per cell of a grid
CELL_MIN_INSTRUCTIONS = 64
#: a hard union of more operands than this is kept whole
MAX_PARTS = 64
_CONTRACT = {"exact": 0, "bound": 1, "neither": 2}


def _hard_union_operands(shape) -> list:
    """The operands of ``shape`` as nested hard unions, flattened (``[shape]`` when its
    root is anything else); a ``color`` or ``material`` node is looked through (its
    geometry is its child's)."""
    if getattr(shape, "name", None) in COLOR_NODES:
        return _hard_union_operands(shape.children[0])
    if getattr(shape, "name", None) != "union" or shape.kwargs.get("k") is not None:
        return [shape]
    out = []
    for c in shape.children:
        out.extend(_hard_union_operands(c))
    return out


_CORNERS = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)])


def _posed_boxes(pose, boxes: np.ndarray) -> np.ndarray:
    """World boxes ``(P, 2, 3)`` holding object-frame boxes ``(P, 2, 3)`` moved by
    ``pose`` (their 8 corners mapped, as :meth:`csdf.Pose.apply_box` does one)."""
    c = np.where(_CORNERS[None, :, :] == 0, boxes[:, None, 0, :], boxes[:, None, 1, :])
    w = pose.apply(c.reshape(-1, 3)).reshape(len(boxes), 8, 3)
    return np.stack([w.min(axis=1), w.max(axis=1)], axis=1)


def union_parts(fld: Field) -> list[tuple[object, np.ndarray, np.ndarray]] | None:
    """The parts of a field whose shape is a hard union: ``[(program, parameter values,
    object-frame box (2, 3))]``, each part compiled on its own; None when the field is
    not such a union, has more than :data:`MAX_PARTS` parts, was given its box, or a
    part has no box. The smallest part value is the field's value. Cached on the
    field's program per parameter values."""
    shape = fld.shape
    if shape is None or fld.dim != 3 or fld._bounds_given is not None:
        return None
    key = tuple(np.asarray(fld.pvals, dtype=np.float64).tolist())

    def make() -> list | None:
        ops = _hard_union_operands(shape)
        if not 1 < len(ops) <= MAX_PARTS:
            return None
        values = dict(zip(fld.program.param_names, key))
        parts = []
        for op in ops:
            try:
                prog = op.compile()
                pv = {n: values[n] for n in prog.param_names}
                box = field_bounds(prog, pv, shape=op)
            except (CsdfError, KeyError):
                return None
            parts.append((prog, prog.param_values(pv, check_ranges=False), box))
        return parts

    return memo(fld.program, "_union_parts", key, make, 8)


def cell_depth(n_instructions: int) -> int:
    """Depth of the grid of cell tapes kept for a model of this many instructions (0:
    none): short tapes gain little from pruning, long ones a finer grid."""
    if n_instructions < CELL_MIN_INSTRUCTIONS:
        return 0
    return 3 if n_instructions < 1000 else 4


class _Pool:
    """Register tapes gathered into one array of rows, with the cell grids of long ones
    (see :mod:`csdf.backends.nearest_kernels` for the layout)."""

    def __init__(self) -> None:
        self.code: list[np.ndarray] = []
        self.imm: list[np.ndarray] = []
        self.tape_i: list[list[int]] = []
        self.tape_f: list[np.ndarray] = []
        self.cells: list[np.ndarray] = []
        self.rows = 0
        self.n_cells = 0

    def add(self, code: np.ndarray, imm: np.ndarray, out: int, regs: int) -> int:
        self.code.append(code)
        self.imm.append(imm)
        self.tape_i.append([self.rows, len(code), int(out), int(regs), 0, 0])
        self.tape_f.append(np.ones(6))
        self.rows += len(code)
        return len(self.tape_i) - 1

    def add_cells(self, t: int, fld: Field, depth: int) -> None:
        """Tapes for every cell of a ``2**depth`` grid over the field's box grown by its
        size on each side (points farther out run the whole tape)."""
        from .backends.pruned import cell_tapes

        box = fld.model_bounds
        size = np.maximum(box[1] - box[0], 1e-6)
        region = np.array([box[0] - size, box[1] + size])
        # cached on the program: a scene rebuilt after an update shortens no tape again
        ct = cell_tapes(fld.program, fld.pvals, region, depth)
        n = 1 << depth
        leaves = ct.tapes(depth, np.arange(n ** 3))
        pool = ct.pool
        ids = np.empty(len(leaves), np.int64)
        first: dict[int, int] = {}
        for c, lt in enumerate(leaves.tolist()):
            got = first.get(lt)
            if got is None:
                a = int(pool.start[lt])
                b = a + int(pool.length[lt])
                got = first[lt] = self.add(pool.code[a:b], pool.imm[a:b], pool.out[lt],
                                           pool.regs[lt])
            ids[c] = got
        self.tape_i[t][4:6] = [n, self.n_cells]
        self.tape_f[t] = np.concatenate([ct.lo, ct.span])
        self.cells.append(ids)
        self.n_cells += len(ids)

    def arrays(self):
        code = np.ascontiguousarray(np.concatenate(self.code), np.int32)
        imm = np.ascontiguousarray(np.concatenate(self.imm), np.float64)
        tape_i = np.array(self.tape_i, dtype=np.int64).reshape(-1, 6)
        tape_f = np.array(self.tape_f, dtype=np.float64).reshape(-1, 6)
        cells = np.concatenate(self.cells) if self.cells else np.zeros(1, np.int64)
        return code, imm, tape_i, tape_f, cells


class FieldSet:
    """Posed 3D fields (instances) with batched nearest and collision queries.

    Args:
        fields: the instances, each a bounded 3D :class:`csdf.field.Field` (its pose
            places it; its parameter values are fixed here).

    Attributes:
        fields: the instances; boxes: ``(K, 2, 3)`` their world boxes.

    Raises:
        CsdfError: no fields, a 2D field, a field without bounds, or no Numba.
    """

    def __init__(self, fields: Sequence[Field]):
        from .backends.pruned import reg_tape

        if not numba_available():
            raise CsdfError("scene queries need Numba (pip install numba)")
        self.fields = list(fields)
        if not self.fields:
            raise CsdfError("a field set needs at least one field")
        K = len(self.fields)
        # id(tape) -> (pool index, the tape): the tape is held so that its id cannot be
        # reused while this runs; reg_tape's cache keeps a few tapes per program, and a
        # tape it dropped and freed could otherwise share its id with the next instance's
        # tape (another parameter set), which then got the freed tape's pool row
        tapes: dict[int, tuple[int, object]] = {}
        pool = _Pool()
        rows_f: list[np.ndarray] = []
        rows_i: list[tuple[int, int]] = []
        owner: list[int] = []
        ent_range: list[tuple[int, int]] = []
        boxes = np.empty((K, 2, 3))

        def tape_row(prog, pvals, fld=None) -> int:
            tape = reg_tape(prog, pvals)
            seen = tapes.get(id(tape))
            if seen is not None:
                return seen[0]
            t = pool.add(tape.code, tape.imm, tape.out, tape.n_regs)
            tapes[id(tape)] = (t, tape)
            depth = cell_depth(len(tape.code)) if fld is not None else 0
            if depth:
                pool.add_cells(t, fld, depth)
            return t

        #: instances evaluated outside the compiled kernel (mesh calls: see nearest)
        self.host: list[int] = []
        for k, fld in enumerate(self.fields):
            if fld.dim != 3:
                raise CsdfError(f"instance {k}: a scene holds 3D fields; extrude or revolve "
                                "a 2D shape first")
            pose = fld.pose
            boxes[k] = fld.bounds
            if fld.program.data:  # a mesh call runs outside the register tapes
                self.host.append(k)
                ent_range.append((len(owner), 0))
                continue
            frame = np.concatenate([pose.rotation.reshape(-1), pose.translation,
                                    [pose.scale]])
            contract = _CONTRACT[fld.exactness]
            parts = union_parts(fld)
            ent_range.append((len(owner), 1 if parts is None else len(parts)))
            if parts is None:
                rows_f.append(np.concatenate([frame, boxes[k, 0], boxes[k, 1]]))
                rows_i.append((tape_row(fld.program, fld.pvals, fld), contract))
                owner.append(k)
                continue
            world = _posed_boxes(pose, np.array([box for _, _, box in parts]))
            for (prog, pvals, _), wb in zip(parts, world):
                rows_f.append(np.concatenate([frame, wb[0], wb[1]]))
                rows_i.append((tape_row(prog, pvals), contract))
                owner.append(k)
            boxes[k, 0] = np.minimum(boxes[k, 0], world[:, 0].min(axis=0))  # holds its
            boxes[k, 1] = np.maximum(boxes[k, 1], world[:, 1].max(axis=0))  # parts' boxes
        if not owner:  # only host instances: the kernel has nothing to run
            pool.add(np.zeros((1, 4), np.int32), np.zeros(1), 0, 1)
        self.code, self.imm, self.tape_i, self.tape_f, self.cell_tab = pool.arrays()
        self.max_regs = int(self.tape_i[:, 3].max())
        #: per entry of the hierarchy (an instance, or one part of a union instance)
        self.inst_f = np.array(rows_f, dtype=np.float64).reshape(-1, 19)
        self.inst_i = np.array(rows_i, dtype=np.int64).reshape(-1, 2)
        #: ``(E,)`` the instance of each entry; ``(K, 2)`` each instance's entries
        self.owner = np.array(owner, dtype=np.int64)
        self.ent_range = np.array(ent_range, dtype=np.int64).reshape(-1, 2)
        self.lipschitz = max(float(f.lipschitz) for f in self.fields)
        self.boxes = boxes
        self.inst_box = np.ascontiguousarray(boxes.reshape(K, 6))
        # a two-level hierarchy: a tree over the instances, then each one's entries
        self.node_f, self.node_i, self.order = build_bvh(boxes[:, 0], boxes[:, 1], LEAF_SIZE)

    def __len__(self) -> int:
        return len(self.fields)

    def nearest(self, points: np.ndarray, *, grad: bool = False,
                below: np.ndarray | None = None, stop: bool = False
                ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray, np.ndarray]:
        """The smallest instance value at each point (see
        :func:`csdf.backends.nearest_kernels.nearest`).

        Args:
            points: ``(N, 3)`` float64 world points.
            grad: also the world gradient of the winning instance.
            below: ``(N,)`` start values of the search (default inf): only instances
                with a value below them count.
            stop: end each search at the first value below ``below`` (collisions).

        Returns:
            ``(value (N,), gradient (N, 3) or None, instance (N,) int64 (-1: none),
            exact (N,) bool)``.
        """
        from .backends import nearest_kernels as NK

        pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
        N = len(pts)
        start = np.full(N, np.inf) if below is None else \
            np.ascontiguousarray(below, dtype=np.float64).reshape(N)
        dist = np.empty(N)
        g = np.empty((N, 3)) if grad else np.empty((1, 3))
        inst = np.empty(N, np.int64)
        exact = np.empty(N, np.bool_)
        args = (pts, start, bool(stop), bool(grad), self.inst_f, self.inst_i, self.code,
                self.imm, self.tape_i, self.tape_f, self.cell_tab, self.node_f,
                self.node_i, self.order, self.inst_box, self.ent_range, self.max_regs, dist,
                g, inst, exact)
        n = 1 if N < SERIAL_BELOW else N_THREADS
        if n == 1:
            NK.nearest(*args, 0, 1)
        else:
            list(executor().map(lambda c: NK.nearest(*args, c, n), range(n)))
        if len(self.owner) != len(self.fields):  # entries -> instances
            inst = np.where(inst >= 0, self.owner[np.maximum(inst, 0)], -1) \
                if len(self.owner) else np.full(N, -1, np.int64)
        if self.host:
            self._host_nearest(pts, start, dist, g if grad else None, inst, exact)
        return dist, (g if grad else None), inst, exact

    def _host_nearest(self, pts: np.ndarray, start: np.ndarray, dist: np.ndarray,
                      g: np.ndarray | None, inst: np.ndarray, exact: np.ndarray) -> None:
        """Fold the host instances (fields with mesh calls, which the compiled kernel
        does not run) into a kernel result, in place: each is evaluated by its field
        (the ``'numpy'`` evaluator, whose mesh query is a multithreaded Numba kernel) at
        the points its world box does not rule out (box distance below the best value
        so far, the kernel's own test), and wins where its value is below the best."""
        for k in self.host:
            fld = self.fields[k]
            box = self.boxes[k]
            best = np.where(inst >= 0, dist, start)
            gap = np.linalg.norm(np.maximum(np.maximum(box[0] - pts, pts - box[1]), 0.0),
                                 axis=1)
            idx = np.flatnonzero((gap <= 0.0) | (gap < best))
            if not len(idx):
                continue
            if g is not None:
                v, vg = fld.value_and_grad(pts[idx])
            else:
                v, vg = fld.value(pts[idx]), None
            with np.errstate(invalid="ignore"):
                win = v < best[idx]
            w = idx[win]
            dist[w] = v[win]
            inst[w] = k
            exact[w] = fld.exactness == "exact"
            if g is not None and vg is not None:
                g[w] = vg[win]
