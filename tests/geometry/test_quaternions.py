"""The quaternion and vector helpers of :mod:`mocapedit.geometry.kinematics`."""
from __future__ import annotations

import numpy as np
import pytest

from mocapedit.geometry import kinematics


@pytest.mark.parametrize("shape_a, shape_b", [((5, 3), (5, 3)), ((4, 1, 3), (1, 6, 3)), ((3,), (7, 3)),
                                              ((2, 5, 3), (3,))])
def test_cross3_is_numpys_cross_value_for_value_broadcast(shape_a, shape_b):
    rng = np.random.default_rng(7)
    a, b = rng.normal(size=shape_a), rng.normal(size=shape_b)
    assert np.array_equal(kinematics.cross3(a, b), np.cross(a, b))


def test_quaternion_rotation_product_and_conjugate_agree_with_rotation_matrices():
    rng = np.random.default_rng(3)
    q = rng.normal(size=(6, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    p = rng.normal(size=(6, 4))
    p /= np.linalg.norm(p, axis=1, keepdims=True)
    v = rng.normal(size=(6, 3))
    # Row vectors: v @ R rotates v by the quaternion.
    r = kinematics.quat_to_matrix3(q)
    assert np.allclose(kinematics.quat_rotate(q, v), np.einsum("ni,nij->nj", v, r), atol=1e-12)
    # q * p rotates by p, then by q.
    both = kinematics.quat_rotate(kinematics.quat_multiply(q, p), v)
    assert np.allclose(both, kinematics.quat_rotate(q, kinematics.quat_rotate(p, v)), atol=1e-12)
    back = kinematics.quat_rotate(kinematics.quat_conjugate(q), kinematics.quat_rotate(q, v))
    assert np.allclose(back, v, atol=1e-12)
