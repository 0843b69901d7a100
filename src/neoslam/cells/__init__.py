"""Brain-inspired cells: grid cells, head-direction cells, object-vector cells and the Hebbian place memory."""

from neoslam.cells.grid_cells import GridCells, circular_difference
from neoslam.cells.head_direction import HeadDirectionCells, wrap_angle
from neoslam.cells.hebbian import HebbianMemory, HebbianRecall
from neoslam.cells.object_vector import ObjectVectorCells, object_vector_field

__all__ = [
    "GridCells",
    "HeadDirectionCells",
    "circular_difference",
    "wrap_angle",
    "HebbianMemory",
    "HebbianRecall",
    "ObjectVectorCells",
    "object_vector_field",
]
