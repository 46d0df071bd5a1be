"""3-vectors as tuples of float32, and orthonormal frames."""
import math


from .constants import LUM_B, LUM_G, LUM_R, ONE, ZERO
from .device import device


@device
def add(a, b):
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2])


@device
def sub(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


@device
def mul(a, b):
    """Component-wise product."""
    return (a[0] * b[0], a[1] * b[1], a[2] * b[2])


@device
def scale(a, s):
    return (a[0] * s, a[1] * s, a[2] * s)


@device
def madd(a, b, s):
    """a + b * s."""
    return (a[0] + b[0] * s, a[1] + b[1] * s, a[2] + b[2] * s)


@device
def neg(a):
    return (-a[0], -a[1], -a[2])


@device
def dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@device
def cross(a, b):
    return (a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0])


@device
def length(a):
    return math.sqrt(dot(a, a))


@device
def normalize(a):
    inv = ONE / math.sqrt(dot(a, a))
    return (a[0] * inv, a[1] * inv, a[2] * inv)


@device
def max_abs(a):
    return max(abs(a[0]), max(abs(a[1]), abs(a[2])))


@device
def max_comp(a):
    return max(a[0], max(a[1], a[2]))


@device
def load3(arr, i, j):
    """arr[i, j:j+3] as a tuple."""
    return (arr[i, j], arr[i, j + 1], arr[i, j + 2])


@device
def frame(n):
    """Tangent and bitangent completing the unit normal n to a right-handed frame.

    Branchless construction of Duff et al. 2017, "Building an Orthonormal Basis, Revisited"
    (JCGT 6(1)); unlike cross(n, up) it has no degenerate direction (the thesis renderer's
    frame collapsed for normals along +-Y).
    """
    sign = ONE if n[2] >= ZERO else -ONE
    a = -ONE / (sign + n[2])
    b = n[0] * n[1] * a
    t = (ONE + sign * n[0] * n[0] * a, sign * b, -sign * n[0])
    s = (b, sign + n[1] * n[1] * a, -n[1])
    return t, s


@device
def to_world(v, t, s, n):
    """Local (x along t, y along s, z along n) to world."""
    return (t[0] * v[0] + s[0] * v[1] + n[0] * v[2],
            t[1] * v[0] + s[1] * v[1] + n[1] * v[2],
            t[2] * v[0] + s[2] * v[1] + n[2] * v[2])


@device
def luminance(r, g, b):
    """Luminance of linear RGB (constants.LUM_*)."""
    return LUM_R * r + LUM_G * g + LUM_B * b
