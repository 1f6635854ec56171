"""The min/max tree of linear pieces: the occupancy function ``F`` and its evaluation."""


from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Union

import numpy as np
from numpy.typing import ArrayLike, NDArray

from occtool.errors import ModelFormatError

if TYPE_CHECKING:
    from occtool.tree._inverse import InverseTree

FloatArray = NDArray[np.float64]

#: Coefficient names of each basis, in column order.
BASES: dict[str, tuple[str, ...]] = {
    "linear": ("a", "b", "c", "d"),
    "trig": ("a1", "a2", "b", "c", "d"),
}
#: Coefficient names of the inverse pieces (``r`` as a function of the angle terms, h, m).
INVERSE_BASES: dict[str, tuple[str, ...]] = {
    "linear": ("a", "b", "m", "d"),
    "trig": ("a1", "a2", "b", "m", "d"),
}

Node = Union[int, "Op"]


@dataclass(frozen=True)
class Op:
    """An inner node: ``op`` is ``"min"`` or ``"max"`` over ``children``."""

    op: str
    children: tuple[Node, ...]

    def to_dict(self) -> dict[str, Any]:
        return {"op": self.op, "children": [c if isinstance(c, int) else c.to_dict() for c in self.children]}

    def swapped(self) -> Op:
        """The same shape with every MIN and MAX exchanged."""
        return Op(
            "min" if self.op == "max" else "max",
            tuple(c if isinstance(c, int) else c.swapped() for c in self.children),
        )


def node_from_dict(data: Any, n_pieces: int, *, where: str = "tree") -> Node:
    """Parse a nested tree dict, checking every piece index; raises :class:`ModelFormatError`."""
    if isinstance(data, bool):
        raise ModelFormatError(f"{where}: expected a piece index or a node, got {data!r}")
    if isinstance(data, int):
        if not 0 <= data < n_pieces:
            raise ModelFormatError(f"{where}: piece index {data} out of range (there are {n_pieces} pieces)")
        return data
    if not isinstance(data, dict) or set(data) != {"op", "children"}:
        raise ModelFormatError(f"{where}: a node must be an object with 'op' and 'children'")
    if data["op"] not in ("min", "max"):
        raise ModelFormatError(f"{where}: node op must be 'min' or 'max', got {data['op']!r}")
    children = data["children"]
    if not isinstance(children, list) or not children:
        raise ModelFormatError(f"{where}: node children must be a non-empty list")
    return Op(data["op"], tuple(node_from_dict(c, n_pieces, where=f"{where}.children[{i}]")
                                for i, c in enumerate(children)))


def leaves(node: Node) -> list[int]:
    """Piece indices under ``node``, left to right."""
    if isinstance(node, int):
        return [node]
    out: list[int] = []
    for child in node.children:
        out.extend(leaves(child))
    return out


def angle_terms(basis: str, alpha: ArrayLike) -> list[FloatArray]:
    """The pan-angle columns of a basis: ``[alpha]`` or ``[cos alpha, sin alpha]``."""
    alpha = np.asarray(alpha, dtype=np.float64)
    if basis == "linear":
        return [alpha]
    if basis == "trig":
        return [np.cos(alpha), np.sin(alpha)]
    raise ModelFormatError(f"unknown basis {basis!r}: expected one of {', '.join(BASES)}")


def design_matrix(basis: str, alpha: ArrayLike, h: ArrayLike, r: ArrayLike) -> FloatArray:
    """``(n, k)`` matrix of basis columns: angle terms, ``h``, ``r``, 1."""
    alpha, h, r = np.broadcast_arrays(np.asarray(alpha, float), np.asarray(h, float), np.asarray(r, float))
    cols = [*angle_terms(basis, alpha.ravel()), h.ravel(), r.ravel(), np.ones(alpha.size)]
    return np.column_stack(cols)


#: Points evaluated at once: a (pieces x points) block of a few megabytes.
EVALUATION_CHUNK = 1 << 12


def _leaf_run(children: tuple[Node, ...]) -> int | None:
    """The first of ``children`` when they are two or more consecutive pieces, else None."""
    first = children[0]
    if len(children) > 1 and isinstance(first, int) and children == tuple(range(first, first + len(children))):
        return first
    return None


def _evaluate(node: Node, values: FloatArray) -> FloatArray:
    if isinstance(node, int):
        return values[node]
    reduce = np.minimum if node.op == "min" else np.maximum
    first = _leaf_run(node.children)
    if first is not None:
        # One reduction over the pieces' rows: the same pairwise MIN/MAX in the same order
        # (a fit's groups are consecutive pieces; a call a piece was most of a chunk's time).
        return reduce.reduce(values[first:first + len(node.children)], axis=0)
    out = _evaluate(node.children[0], values)
    if len(node.children) > 1 and out.base is not None:
        out = out.copy()  # a row of ``values`` (a leaf's, or a one-child node's): reduced into in place below
    for child in node.children[1:]:
        # In place: the same pairwise MIN/MAX in the same order, without a fresh array a child.
        reduce(out, _evaluate(child, values), out=out)
    return out


def _evaluate_active(node: Node, values: FloatArray) -> tuple[FloatArray, NDArray[np.intp]]:
    if isinstance(node, int):
        return values[node], np.full(values.shape[1], node, dtype=np.intp)
    out, active = _evaluate_active(node.children[0], values)
    for child in node.children[1:]:
        value, child_active = _evaluate_active(child, values)
        better = value < out if node.op == "min" else value > out
        out = np.where(better, value, out)
        active = np.where(better, child_active, active)
    return out, active


class _PieceTree:
    """Shared machinery of :class:`MinMaxTree` and :class:`InverseTree`."""

    _names: dict[str, tuple[str, ...]]

    def __init__(self, basis: str, coefficients: ArrayLike, root: Node) -> None:
        if basis not in self._names:
            raise ModelFormatError(f"unknown basis {basis!r}: expected one of {', '.join(self._names)}")
        coefficients = np.array(coefficients, dtype=np.float64, ndmin=2)
        width = len(self._names[basis])
        if coefficients.ndim != 2 or coefficients.shape[1] != width or coefficients.shape[0] == 0:
            raise ModelFormatError(
                f"basis {basis!r} needs pieces of {width} coefficients, got shape {coefficients.shape}")
        if not np.isfinite(coefficients).all():
            raise ModelFormatError("a piece coefficient is NaN or infinite")
        used = leaves(root)
        if sorted(set(used)) != list(range(coefficients.shape[0])) or len(used) != len(set(used)):
            raise ModelFormatError("the tree must use every piece exactly once")
        coefficients.setflags(write=False)
        self.basis = basis
        self.coefficients = coefficients
        self.root = root

    @property
    def n_pieces(self) -> int:
        """Number of linear pieces."""
        return int(self.coefficients.shape[0])

    def _values(self, alpha: ArrayLike, h: ArrayLike, x: ArrayLike) -> tuple[FloatArray, tuple[int, ...]]:
        """Every piece's value at every point: ``(L, n)``, one contiguous row per piece."""
        alpha, h, x = (np.asarray(v, dtype=np.float64) for v in (alpha, h, x))
        shape = np.broadcast_shapes(alpha.shape, h.shape, x.shape)
        lead = (self.n_pieces,) + (1,) * len(shape)
        # Each term is formed on its own (un-broadcast) input, smallest first, so a sweep of
        # N angles x H heights computes N cosines and H products and only the last sum is
        # full size; no matrix product (a multi-threaded BLAS made these small products
        # several times slower on a busy 2-core machine). Rows per piece keep the MIN/MAX
        # reductions on contiguous memory.
        terms = sorted(zip([*angle_terms(self.basis, alpha), h, x], self.coefficients[:, :-1].T),
                       key=lambda term: term[0].size)
        values: FloatArray = self.coefficients[:, -1].reshape(lead)
        full_size = (self.n_pieces, *shape)
        buffer: FloatArray | None = None
        for column, weights in terms:
            if buffer is None and values.shape == full_size and values.base is None:
                # Full size and our own array: the remaining terms in place, through one
                # scratch buffer (the same sums in the same order, without two temporaries
                # of pieces x points per term).
                buffer = np.empty(full_size)
            if buffer is None:
                values = values + weights.reshape(lead) * column
            else:
                values += np.multiply(weights.reshape(lead), column, out=buffer)
        full = np.broadcast_to(values, full_size)
        return full.reshape(self.n_pieces, -1), shape

    def _chunked(self, reduce: Any, alpha: ArrayLike, h: ArrayLike, x: ArrayLike) -> NDArray[Any]:
        alpha, h, x = (np.asarray(v, dtype=np.float64) for v in (alpha, h, x))
        shape = np.broadcast_shapes(alpha.shape, h.shape, x.shape)
        size = int(np.prod(shape))
        if size <= EVALUATION_CHUNK:
            values, _ = self._values(alpha, h, x)
            return reduce(values).reshape(shape)
        # Many points (a fit's samples): in chunks, so the (pieces x points) values stay in
        # cache instead of filling hundreds of megabytes (2.2 s -> 0.3 s for 2M samples),
        # each chunk's values formed in the same two buffers (fresh ones a chunk were half
        # the time of a fit's loss at 10k features: new pages every time).
        flat = [np.broadcast_to(v, shape).ravel() for v in (alpha, h, x)]
        buffers = np.empty((2, self.n_pieces, EVALUATION_CHUNK))
        result: NDArray[Any] | None = None
        for i in range(0, size, EVALUATION_CHUNK):
            alpha_part, h_part, x_part = (v[i:i + EVALUATION_CHUNK] for v in flat)
            part = reduce(self._chunk_values(alpha_part, h_part, x_part, buffers))
            if result is None:
                result = np.empty(size, dtype=part.dtype)
            result[i:i + part.size] = part
        assert result is not None
        return result.reshape(shape)

    def _chunk_values(self, alpha: FloatArray, h: FloatArray, x: FloatArray, buffers: FloatArray) -> FloatArray:
        """:meth:`_values` of ``n`` points given as three ``(n,)`` arrays, written into
        ``buffers[0]`` (``buffers[1]`` is scratch): the same sums in the same order (the
        offset added to the first term's product, then each further product)."""
        n = alpha.size
        values, scratch = buffers[0, :, :n], buffers[1, :, :n]
        terms = zip([*angle_terms(self.basis, alpha), h, x], self.coefficients[:, :-1].T)
        for j, (column, weights) in enumerate(terms):
            if j == 0:
                np.multiply(weights[:, None], column, out=values)
                values += self.coefficients[:, -1][:, None]
            else:
                values += np.multiply(weights[:, None], column, out=scratch)
        return values

    def _eval(self, alpha: ArrayLike, h: ArrayLike, x: ArrayLike) -> FloatArray:
        return self._chunked(lambda values: _evaluate(self.root, values), alpha, h, x)

    def _active(self, alpha: ArrayLike, h: ArrayLike, x: ArrayLike) -> NDArray[np.intp]:
        return self._chunked(lambda values: _evaluate_active(self.root, values)[1], alpha, h, x)

    def pieces(self) -> list[dict[str, float]]:
        """The pieces as ``{name: coefficient}`` dicts."""
        names = self._names[self.basis]
        return [{n: float(v) for n, v in zip(names, row)} for row in self.coefficients]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form: basis, pieces (named coefficients) and the nested tree."""
        tree = self.root.to_dict() if isinstance(self.root, Op) else self.root
        return {"basis": self.basis, "pieces": self.pieces(), "tree": tree}

    @classmethod
    def from_dict(cls, data: Any):
        """Rebuild from :meth:`to_dict`, validating; raises :class:`ModelFormatError`."""
        if not isinstance(data, dict):
            raise ModelFormatError("a tree must be a JSON object")
        for key in ("basis", "pieces", "tree"):
            if key not in data:
                raise ModelFormatError(f"the tree has no '{key}'")
        basis = data["basis"]
        if not isinstance(basis, str) or basis not in cls._names:
            raise ModelFormatError(f"unknown basis {basis!r}: expected one of {', '.join(cls._names)}")
        names = cls._names[basis]
        pieces = data["pieces"]
        if not isinstance(pieces, list) or not pieces:
            raise ModelFormatError("'pieces' must be a non-empty list")
        rows = []
        for i, piece in enumerate(pieces):
            if not isinstance(piece, dict) or set(piece) != set(names):
                raise ModelFormatError(f"piece {i} must have exactly the coefficients {', '.join(names)}")
            row = []
            for n in names:
                v = piece[n]
                if isinstance(v, bool) or not isinstance(v, (int, float)):
                    raise ModelFormatError(f"piece {i} coefficient {n} is not a number: {v!r}")
                row.append(float(v))
            rows.append(row)
        root = node_from_dict(data["tree"], len(rows))
        return cls(basis, np.array(rows), root)

    def describe(self) -> str:
        """The tree as a compact formula, e.g. ``max(min(p0, p1), p2)``."""

        def text(node: Node) -> str:
            if isinstance(node, int):
                return f"p{node}"
            return f"{node.op}({', '.join(text(c) for c in node.children)})"

        return text(self.root)

    def depth(self) -> int:
        """Number of node levels above the pieces."""

        def depth(node: Node) -> int:
            return 0 if isinstance(node, int) else 1 + max(depth(c) for c in node.children)

        return depth(self.root)

    def __eq__(self, other: object) -> bool:
        return (
            type(other) is type(self)
            and self.basis == other.basis
            and self.root == other.root
            and np.array_equal(self.coefficients, other.coefficients)
        )

    def __repr__(self) -> str:
        return f"{type(self).__name__}(basis={self.basis!r}, pieces={self.n_pieces}, tree={self.describe()})"


class MinMaxTree(_PieceTree):
    """The occupancy function ``m = F(alpha, h, r)``: MIN/MAX nodes over linear pieces.

    Parameters
    ----------
    basis
        ``"linear"`` (``a*alpha + b*h + c*r + d``) or ``"trig"``
        (``a1*cos(alpha) + a2*sin(alpha) + b*h + c*r + d``).
    coefficients
        ``(L, k)`` piece coefficients in the order of :data:`BASES`.
    root
        The tree: a piece index or an :class:`Op`. Every piece appears exactly once.

    Examples
    --------
    >>> tree = MinMaxTree("linear", [[0, 0, 1.0, -1.0], [0, 0, 2.0, -1.0]], Op("max", (0, 1)))
    >>> float(tree.predict(0.0, 0.0, 1.0))
    1.0
    >>> float(tree.inverse().range(0.0, 0.0, 1.0))
    1.0
    """

    _names = BASES

    @property
    def c(self) -> FloatArray:
        """Range weight ``c`` of each piece."""
        return self.coefficients[:, -2]

    @property
    def b(self) -> FloatArray:
        """Height weight ``b`` of each piece."""
        return self.coefficients[:, -3]

    @property
    def angle_weight(self) -> FloatArray:
        """Largest ``|dF/dalpha|`` of each piece: ``|a|``, or ``hypot(a1, a2)`` for ``trig``."""
        k = len(angle_terms(self.basis, 0.0))
        return np.hypot.reduce(np.abs(self.coefficients[:, :k]), axis=1) if k > 1 else np.abs(self.coefficients[:, 0])

    def predict(self, alpha: ArrayLike, h: ArrayLike, r: ArrayLike) -> FloatArray:
        """Evaluate ``F(alpha, h, r)`` (inputs broadcast together)."""
        return self._eval(alpha, h, r)

    def active_piece(self, alpha: ArrayLike, h: ArrayLike, r: ArrayLike) -> NDArray[np.intp]:
        """Index of the piece that gives ``F`` its value at each point."""
        return self._active(alpha, h, r)

    def inverse(self) -> InverseTree:
        """The inverse tree ``r = F^-1(alpha, h, m)``: MIN and MAX swapped, pieces solved for r.

        Raises
        ------
        ValueError
            If a piece has ``c <= 0`` (the function is then not invertible in ``r``).
        """
        c = self.c
        if not (c > 0).all():
            raise ValueError("the tree is invertible only when every piece has c > 0")
        k = len(angle_terms(self.basis, 0.0))
        inv = np.empty_like(self.coefficients)
        inv[:, :k] = -self.coefficients[:, :k] / c[:, None]
        inv[:, k] = -self.coefficients[:, k] / c
        inv[:, k + 1] = 1.0 / c
        inv[:, k + 2] = -self.coefficients[:, k + 2] / c
        root = self.root.swapped() if isinstance(self.root, Op) else self.root
        from occtool.tree._inverse import InverseTree  # the inverse builds on this module

        return InverseTree(self.basis, inv, root)
