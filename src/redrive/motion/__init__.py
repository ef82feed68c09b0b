"""Motion models shared by the world and the reference algorithms (layer L1, beside geometry).

:mod:`redrive.sim` and :mod:`redrive.algorithms` are siblings and never import each other; what
both need of a driver model lives here, once: the Intelligent Driver Model
(:mod:`redrive.motion.idm`), a compiled kernel that the world's kernels, the reference planner's
kernels and plain Python (:func:`idm_acceleration`) all call; and nuPlan's LQR tracking math
(:mod:`redrive.motion.lqr`: reference-profile fits and the one-step LQR laws) that the closed
loop's built-in tracker and NAVSIM's proposal simulation share.
"""

from __future__ import annotations

from redrive.motion.idm import IdmParams, idm_acceleration, idm_kernel

__all__ = ["IdmParams", "idm_acceleration", "idm_kernel"]
