"""Geometric primitives: exact signed distances, gradients, closest points, segment and capsule
clearances, and bounded obstacles for simulated environments.

Sign convention (see :mod:`wholearm_tools.geometry.base`): negative inside closed shapes,
positive on the normal side of lines and planes; ``clearance = free_side * signed_distance``.
"""

from wholearm_tools.geometry.base import (
    PRIMITIVE_TYPES,
    Primitive,
    as_points,
    primitive_from_dict,
    primitive_to_dict,
    primitive_type,
    register,
)
from wholearm_tools.geometry.bounded import (
    OBSTACLE_TYPES,
    Arc2D,
    CylinderJunction,
    CylinderSection,
    Obstacle,
    PlanePatch,
    Segment2D,
    Surface,
    obstacle_from_dict,
    register_obstacle,
)
from wholearm_tools.geometry.primitives import (
    Circle2D,
    Cone,
    Cylinder,
    Line2D,
    Plane,
    Sphere,
    Torus,
    capsule_clearance,
)

__all__ = [
    "OBSTACLE_TYPES",
    "PRIMITIVE_TYPES",
    "Arc2D",
    "Circle2D",
    "Cone",
    "Cylinder",
    "CylinderJunction",
    "CylinderSection",
    "Line2D",
    "Obstacle",
    "Plane",
    "PlanePatch",
    "Primitive",
    "Segment2D",
    "Sphere",
    "Surface",
    "Torus",
    "as_points",
    "capsule_clearance",
    "obstacle_from_dict",
    "primitive_from_dict",
    "primitive_to_dict",
    "primitive_type",
    "register",
    "register_obstacle",
]
