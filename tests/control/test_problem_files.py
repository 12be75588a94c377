"""The entries of control and fit problem files (`gnipy.control.problem_files`): a group element is
checked by the system's own group, so a model on SE(2) takes its homogeneous matrices and a model
on SO(3) only rotations."""

import numpy as np
import pytest

import gnipy
from gnipy.control.problem_files import entry_rotation


def test_an_se2_element_is_accepted_where_a_rotation_test_would_refuse_it():
    system = gnipy.make_system("chaplygin-sleigh-se2")
    c, s = np.cos(0.3), np.sin(0.3)
    g = np.array([[c, -s, 2.0], [s, c, -1.0], [0.0, 0.0, 1.0]])  # RᵀR ≠ I: not a rotation, an SE(2) element
    np.testing.assert_array_equal(entry_rotation("start.R0", g.tolist(), system), g)


def test_a_matrix_that_is_not_a_rotation_is_refused_on_so3():
    system = gnipy.make_system("rolling-ball")
    with pytest.raises(gnipy.InputError, match=r"^start\.R0: not a rotation matrix \(\|RᵀR − I\| = "):
        entry_rotation("start.R0", np.diag([1.0, 1.0, 1.1]).tolist(), system)
    with pytest.raises(gnipy.InputError, match=r"det = -1"):
        entry_rotation("start.R0", np.diag([1.0, 1.0, -1.0]).tolist(), system)
