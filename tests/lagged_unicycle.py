"""A copy of the unicycle (models/kinematic.py) with one more state slot, defined outside the
package (tests/test_law_seam.py): the speed V follows its input through a first-order lag of
time constant TAU = P[i, 0] [s] (a drivetrain lag), dV/dt = (u0 - V) / TAU."""
import math

from numba import njit

SLOTS = ("X", "Y", "PSI", "V")


@njit(cache=False)
def rhs_into(s, u0, u1, P, i, out):
    out[0] = s[3] * math.cos(s[2])
    out[1] = s[3] * math.sin(s[2])
    out[2] = u1
    out[3] = (u0 - s[3]) / P[i, 0]
