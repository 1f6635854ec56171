"""The min/max tree of linear pieces: the occupancy function and its inverse.

The occupancy function is ``m = F(alpha, h, r)``, a tree of MIN and MAX nodes whose
leaves are linear pieces. Two bases are supported:

``"linear"``
    The paper's pieces ``a*alpha + b*h + c*r + d``. The pan angle jumps from pi to -pi
    behind the robot, so a piece cannot be continuous across that seam.
``"trig"``
    Seam-free pieces ``a1*cos(alpha) + a2*sin(alpha) + b*h + c*r + d``: still linear in
    ``h`` and ``r`` (so the inverse stays in closed form), periodic in ``alpha``.

With ``c > 0`` every piece, and so the tree, is strictly increasing in ``r``; each piece
then has the closed-form inverse ``r = (m - a-terms - b*h - d) / c``. Because a MAX of
increasing functions is at least ``m`` exactly when one child is, the inverse of a MAX
node is the MIN of its children's inverses (and vice versa): :meth:`MinMaxTree.inverse`
swaps MIN and MAX and solves every piece for ``r``.

A tree is written as a nested dict: ``{"op": "max", "children": [{"op": "min",
"children": [0, 1, 2]}, 3]}``, where integers are piece indices.
"""

from occtool.tree._inverse import InverseTree
from occtool.tree._minmax import (
    BASES,
    EVALUATION_CHUNK,
    INVERSE_BASES,
    MinMaxTree,
    Op,
    design_matrix,
    leaves,
    node_from_dict,
)

__all__ = [
    "BASES", "EVALUATION_CHUNK", "INVERSE_BASES", "InverseTree", "MinMaxTree", "Op", "design_matrix", "leaves",
    "node_from_dict",
]
