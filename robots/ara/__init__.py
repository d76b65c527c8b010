"""ARA bridge-inspection robot: two magnetic wheeled feet and a 6-DoF arm.

Seed 000 §3.2 / Fig. 3.2: in mobile mode both feet drive on differential
wheels with their magnet arrays untouched (≈1 mm gap); in inch-worm mode one
foot's array is touched (stuck to the steel) and the arm swings the other
foot to the next surface.  Joints 2 and 5 rotate about y, joints 1, 3, 4, 6
about z.  The model is read from ``ara.urdf``: ``fk``/``jacobian`` give the
sole frame of foot 1 (``foot1_sole``, the chain's last link) in ``base_link``
(the sole of foot 2), and ``ik`` solves numerically (batched damped least
squares from many seeds: the chain has no closed form because joints 3 and 4
are parallel but the wrist axes do not intersect).
"""

from robots.ara.model import (
    HERE,
    PARAMS_PATH,
    URDF_PATH,
    AraModel,
    CollisionShape,
    load,
)

__all__ = [
    "HERE",
    "PARAMS_PATH",
    "URDF_PATH",
    "AraModel",
    "CollisionShape",
    "load",
]
