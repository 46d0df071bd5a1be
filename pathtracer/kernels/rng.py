"""Stateless counter-based random numbers, identical on every backend.

A sample is a pure function of (pixel, sample index, dimension, seed): nothing is stored
between calls, so CPU threads, CUDA threads and the interpreted backend all draw the same
stream, and any single path can be replayed alone (``--backend python --pixel``).

The hash is PCG's output permutation used as a hash (Jarzynski & Olano 2020, "Hash
Functions for GPU Rendering", JCGT 9(3)). Values are uint64 holding 32 bits, masked after
every step: compiled code and interpreted NumPy then agree bit for bit, and no int64 operand
sneaks in (int64 op uint64 is typed float64 by Numba). Numba types every integer operation
64-bit, and LLVM keeps the masked 64-bit multiplies and shifts (half of the GPU kernel's
instructions were 64-bit integer ones, each two or more 32-bit instructions on the GPU), so
the hashes themselves are written for compiled code in 32-bit LLVM IR (``_ir32``: the same
arithmetic modulo 2**32, one ``brev.b32`` for a bit reversal); the plain Python bodies
below are what the interpreted backend and the CUDA simulator run, and the tests check
that both agree.

Two samplers draw from these hashes (``make_sampler``): ``independent`` (one hash per
dimension, as pbrt's IndependentSampler) and ``sobol``, the default: Owen-scrambled Sobol
points (Burley 2020, "Practical Hash-based Owen Scrambling", JCGT 9(4)), low discrepancy per
pixel, decorrelated between pixels by per-pixel scrambling seeds.

Dimension layout of one path (``kernels.layout``, D_*): dimensions come in sets of four, and
the sobol sampler draws each set from the 4-D Sobol sequence with its own index shuffle
(Burley's padding): set 0 is the camera (pixel x, pixel y, lens u, lens v); every
scattering event then has two sets, the light sample (position u, v, light pick) and the BSDF
sample (direction u, v, reflection or refraction, Russian roulette: the principled BSDF picks
its lobe by reusing u, ``principled.reuse_sample``). The CPU opens a bounce's two sets
together (``make_pair_opener``, ``sobol_floats_pair``): the same numbers, fewer vector
operations.
"""
import inspect

import numpy as np
from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic, overload

from .device import device

M32 = np.uint64(0xFFFFFFFF)
_MUL = np.uint64(747796405)
_INC = np.uint64(2891336453)
_MUL2 = np.uint64(277803737)
_GOLDEN = np.uint64(0x9E3779B9)
_S4 = np.uint64(4)
_S8 = np.uint64(8)
_S22 = np.uint64(22)
_S28 = np.uint64(28)
_TO_UNIT = np.float32(1.0 / 16777216.0)


_I32 = ir.IntType(32)
_I64 = ir.IntType(64)


def _ir32(body):
    """Compile the decorated plain-Python function (uint64 arguments below 2**32, a uint64
    result below 2**32) through ``body(builder, *i32 values) -> i32 value`` in compiled
    code: the arguments are truncated to i32, the result zero-extended to uint64. The
    Python function stays what the interpreted backend calls."""
    def wrap(fn):
        nargs = fn.__code__.co_argcount

        def typer(typingctx, *args):
            if len(args) != nargs or not all(isinstance(a, types.Integer) for a in args):
                return None
            sig = types.uint64(*args)

            def codegen(context, builder, signature, values):
                r = body(builder, *[builder.trunc(v, _I32) if v.type.width > 32 else
                                    builder.zext(v, _I32) if v.type.width < 32 else v
                                    for v in values])
                return builder.zext(r, _I64)
            return sig, codegen
        typer.__name__ = f"_{fn.__name__}_ir32"
        # (intrinsic reads the typing function's signature: the context, then the arguments)
        typer.__signature__ = inspect.Signature(
            [inspect.Parameter(n, inspect.Parameter.POSITIONAL_OR_KEYWORD)
             for n in ("typingctx",) + fn.__code__.co_varnames[:nargs]])
        compiled = intrinsic(typer)
        overload(fn, strict=False)(lambda *args: (lambda *a: compiled(*a)))
        return fn
    return wrap


def _c(v, like=None):
    """The 32-bit constant v; where ``like`` (an IR value) is a vector of i32, v in every
    lane, so that the hashes' IR below serves scalars and vectors alike."""
    if like is not None and isinstance(like.type, ir.VectorType):
        return ir.Constant(like.type, [ir.Constant(_I32, int(v) & 0xFFFFFFFF)]
                           * like.type.count)
    return ir.Constant(_I32, int(v))


def _pcg_ir(b, x):
    state = b.add(b.mul(x, _c(_MUL, x)), _c(_INC, x))
    shift = b.add(b.lshr(state, _c(28, x)), _c(4, x))
    word = b.mul(b.xor(b.lshr(state, shift), state), _c(_MUL2, x))
    return b.xor(b.lshr(word, _c(22, x)), word)


@_ir32(_pcg_ir)
def pcg_hash(x):
    """32-bit -> 32-bit hash; x is a uint64 below 2**32."""
    state = (x * _MUL + _INC) & M32
    word = (((state >> ((state >> _S28) + _S4)) ^ state) * _MUL2) & M32
    return (word >> _S22) ^ word


def _udiv_ir(b, a, n):
    return b.udiv(a, n)


@_ir32(_udiv_ir)
def udiv32(a, n):
    """a // n of integers 0 <= a < 2**32 and 0 < n < 2**32, as a uint64: in compiled code
    one 32-bit division (Numba divides 64-bit integers, which the GPU runs as a routine of
    ~70 instructions, twice the 32-bit one's)."""
    return np.uint64(a) // np.uint64(n)


@device
def pixel_key(pixel, seed):
    """Key of one pixel's samples; pixel and seed are non-negative integers < 2**32."""
    return pcg_hash((pcg_hash(np.uint64(seed) & M32) + np.uint64(pixel)) & M32)


@device
def path_key(pixel, sample, seed):
    """Key of one camera path; pixel, sample and seed are non-negative integers < 2**32."""
    return pcg_hash((pixel_key(pixel, seed) + np.uint64(sample)) & M32)


@device
def sample_1d(key, dim):
    """Uniform float32 in [0, 1) for dimension ``dim`` of the path with ``key``."""
    h = pcg_hash((key + np.uint64(dim) * _GOLDEN) & M32)
    return np.float32(h >> _S8) * _TO_UNIT


# ---------------------------------------------------------------------------------------
# Owen-scrambled Sobol (Burley 2020)

SOBOL_DIMS = 4          # dimensions per set (the Sobol sequence's first four)
SOBOL_BITS = 32
_K1 = np.uint64(1)


def sobol_matrices():
    """Generator matrices (as direction numbers, uint64 holding 32 bits; row d, column k:
    the contribution of index bit k) of the first four Sobol dimensions, from Joe & Kuo's
    primitive polynomials and initial numbers (new-joe-kuo-6.21201): dimension 0 is van der
    Corput; then (s, a, m) = (1, 0, [1]), (2, 1, [1, 3]), (3, 1, [1, 3, 1])."""
    params = [(1, 0, [1]), (2, 1, [1, 3]), (3, 1, [1, 3, 1])]
    v = np.zeros((SOBOL_DIMS, SOBOL_BITS), np.uint64)
    v[0] = [1 << (31 - k) for k in range(SOBOL_BITS)]
    for d, (s, a, m) in enumerate(params, start=1):
        w = [0] * SOBOL_BITS
        for k in range(s):
            w[k] = m[k] << (31 - k)
        for k in range(s, SOBOL_BITS):
            w[k] = w[k - s] ^ (w[k - s] >> s)
            for j in range(1, s):
                if (a >> (s - 1 - j)) & 1:
                    w[k] ^= w[k - j]
        v[d] = w
    return v


SOBOL_MATRIX = sobol_matrices()
_B1 = np.uint64(1)
_B2 = np.uint64(2)
_B16 = np.uint64(16)
_MASK1 = np.uint64(0x55555555)
_MASK2 = np.uint64(0x33333333)
_MASK4 = np.uint64(0x0F0F0F0F)
_MASK8 = np.uint64(0x00FF00FF)
_TOP = np.uint64(0x80000000)
# the scramble's multipliers: Vegdahl's improvement of Burley's Laine-Karras hash
# ("Building a better LK hash", 2021; as Cycles uses)
_LK0 = np.uint64(0x3d20adea)
_LK1 = np.uint64(0x05526c56)
_LK2 = np.uint64(0x53a22864)
_SET_MUL = np.uint64(0x85EBCA6B)   # odd constants spreading set and dimension numbers
_DIM_MUL = np.uint64(0xC2B2AE35)


def _brev_ir(b, x):
    if isinstance(x.type, ir.VectorType):
        # (llvmlite's declare_intrinsic names no vector types)
        fn = cgutils.get_or_insert_function(
            b.module, ir.FunctionType(x.type, [x.type]),
            f"llvm.bitreverse.v{x.type.count}i32")
        return b.call(fn, [x])
    return b.call(b.module.declare_intrinsic("llvm.bitreverse", [_I32]), [x])


@_ir32(_brev_ir)
def reverse_bits(x):
    """The 32 bits of x (a uint64 below 2**32) in reverse order."""
    x = ((x >> _B1) & _MASK1) | ((x & _MASK1) << _B1)
    x = ((x >> _B2) & _MASK2) | ((x & _MASK2) << _B2)
    x = ((x >> _S4) & _MASK4) | ((x & _MASK4) << _S4)
    x = ((x >> _S8) & _MASK8) | ((x & _MASK8) << _S8)
    return ((x >> _B16) | (x << _B16)) & M32


def _lk_ir(b, x, seed):
    x = b.xor(x, b.mul(x, _c(_LK0, x)))
    x = b.add(x, seed)
    x = b.mul(x, b.or_(b.lshr(seed, _c(16, x)), _c(1, x)))
    x = b.xor(x, b.mul(x, _c(_LK1, x)))
    return b.xor(x, b.mul(x, _c(_LK2, x)))


@_ir32(_lk_ir)
def lk_permutation(x, seed):
    """The Owen scramble in bit-reversed order (x and the result reversed): every step
    changes a bit only as a function of the bits below it (x * even, + seed, * odd), i.e. of
    the more significant bits of the unreversed number (Burley 2020, listing 3, with
    Vegdahl's constants). Products of numbers below 2**32 fit in the uint64."""
    x ^= (x * _LK0) & M32
    x = (x + seed) & M32
    x = (x * ((seed >> _B16) | _K1)) & M32
    x ^= (x * _LK1) & M32
    x ^= (x * _LK2) & M32
    return x


def _sobol_digits_py(u):
    """Dimensions 1-3 of the Sobol point of index u (a uint64 below 2**32), each a 32-bit
    fraction in reversed bit order (dimension 0 is u itself: van der Corput reversed). The
    direction numbers are generated as the loop goes, from their recurrences (Joe & Kuo; see
    sobol_matrices) in reversed bit order, where a right shift becomes a left shift:
    dimension 1 v[k+1] = v[k] ^ v[k] << 1; dimension 2 v[k+2] = v[k] ^ v[k] << 2 ^ v[k+1]
    from (1, 3); dimension 3 v[k+3] = v[k] ^ v[k] << 3 ^ v[k+1] from (1, 3, 4). No table:
    on the GPU a table lookup indexed by a lane's own bit number serialises in the
    constant cache."""
    x1 = x2 = x3 = np.uint64(0)
    a = np.uint64(1)
    b0, b1 = np.uint64(1), np.uint64(3)
    c0, c1, c2 = np.uint64(1), np.uint64(3), np.uint64(4)
    while u != 0:
        if u & _K1:
            x1 ^= a
            x2 ^= b0
            x3 ^= c0
        a = (a ^ (a << _B1)) & M32
        b0, b1 = b1, (b0 ^ (b0 << _B2) ^ b1) & M32
        c0, c1, c2 = c1, c2, (c0 ^ (c0 << np.uint64(3)) ^ c1) & M32
        u >>= _K1
    return x1, x2, x3


@intrinsic
def _sobol_digits_ir(typingctx, u):
    """_sobol_digits_py in 32-bit LLVM IR: a loop over u's bits with branch-free XORs."""
    if not isinstance(u, types.Integer):
        return None
    sig = types.UniTuple(types.uint64, 3)(u)

    def codegen(context, builder, signature, values):
        (v,) = values
        u0 = builder.trunc(v, _I32) if v.type.width > 32 else (
            builder.zext(v, _I32) if v.type.width < 32 else v)
        entry = builder.block
        loop = builder.append_basic_block("sobol.loop")
        body = builder.append_basic_block("sobol.body")
        done = builder.append_basic_block("sobol.done")
        builder.branch(loop)
        builder.position_at_end(loop)
        names = ("u", "x1", "x2", "x3", "a", "b0", "b1", "c0", "c1", "c2")
        start = (u0, _c(0), _c(0), _c(0), _c(1), _c(1), _c(3), _c(1), _c(3), _c(4))
        phi = {n: builder.phi(_I32, name="sobol." + n) for n in names}
        for n, s0 in zip(names, start):
            phi[n].add_incoming(s0, entry)
        builder.cbranch(builder.icmp_unsigned("!=", phi["u"], _c(0)), body, done)
        builder.position_at_end(body)
        mask = builder.sub(_c(0), builder.and_(phi["u"], _c(1)))
        nxt = {"u": builder.lshr(phi["u"], _c(1)),
               "x1": builder.xor(phi["x1"], builder.and_(phi["a"], mask)),
               "x2": builder.xor(phi["x2"], builder.and_(phi["b0"], mask)),
               "x3": builder.xor(phi["x3"], builder.and_(phi["c0"], mask)),
               "a": builder.xor(phi["a"], builder.shl(phi["a"], _c(1))),
               "b0": phi["b1"],
               "b1": builder.xor(builder.xor(phi["b0"], builder.shl(phi["b0"], _c(2))),
                                 phi["b1"]),
               "c0": phi["c1"],
               "c1": phi["c2"],
               "c2": builder.xor(builder.xor(phi["c0"], builder.shl(phi["c0"], _c(3))),
                                 phi["c1"])}
        end = builder.block
        for n in names:
            phi[n].add_incoming(nxt[n], end)
        builder.branch(loop)
        builder.position_at_end(done)
        out = [builder.zext(phi[n], _I64) for n in ("x1", "x2", "x3")]
        return context.make_tuple(builder, signature.return_type, out)
    return sig, codegen


overload(_sobol_digits_py, strict=False)(lambda u: (lambda u: _sobol_digits_ir(u)))
sobol_digits = _sobol_digits_py


def _sobol_byte_table():
    """SOBOL_BYTES[k, b, d - 1]: dimension d (1-3) of the Sobol point of index b << 8k, as
    sobol_digits gives it. The points are linear over GF(2) in the index's bits, so the
    digits of any index are the XOR of its four bytes' rows. (The fourth column, zeros,
    pads an entry to 16 bytes.)"""
    t = np.zeros((4, 256, 4), np.uint32)
    for k in range(4):
        for b in range(256):
            t[k, b, :3] = _sobol_digits_py(np.uint64(b << (8 * k)))
    return t


SOBOL_BYTES = _sobol_byte_table()
_B255 = np.uint64(255)
_S16 = np.uint64(16)
_S24 = np.uint64(24)


@device
def sobol_digits_table(u):
    """sobol_digits(u) from SOBOL_BYTES: four table rows instead of a loop over u's bits
    (the CPU's form: one L1-resident 16 KB table; the GPU keeps the loop, see
    sobol_digits)."""
    tab = SOBOL_BYTES
    b0 = u & _B255
    if u <= _B255:
        # the first 256 samples of a pixel (their shuffled indices stay below 256, see
        # sobol_set): the other three bytes' rows are zeros, nine loads saved
        return (np.uint64(tab[0, b0, 0]), np.uint64(tab[0, b0, 1]),
                np.uint64(tab[0, b0, 2]))
    b1 = (u >> _S8) & _B255
    b2 = (u >> _S16) & _B255
    b3 = (u >> _S24) & _B255
    x1 = np.uint64(tab[0, b0, 0] ^ tab[1, b1, 0] ^ tab[2, b2, 0] ^ tab[3, b3, 0])
    x2 = np.uint64(tab[0, b0, 1] ^ tab[1, b1, 1] ^ tab[2, b2, 1] ^ tab[3, b3, 1])
    x3 = np.uint64(tab[0, b0, 2] ^ tab[1, b1, 2] ^ tab[2, b2, 2] ^ tab[3, b3, 2])
    return x1, x2, x3


@device
def owen_scramble(x, seed):
    """Nested uniform (Owen) scramble of the 32-bit fraction x (Burley 2020, listing 4)."""
    return reverse_bits(lk_permutation(reverse_bits(x), seed))


@device
def sobol_set(pix, index_reversed, dset):
    """The Sobol coordinates (dimensions 0-3, each a 32-bit fraction in reversed bit order)
    of one sample in dimension set ``dset`` of the pixel with key ``pix``, and the set's
    seed: (x0, x1, x2, x3, seed). ``index_reversed``: the sample index, bits reversed.

    Every set has its own shuffle of the sample index (Burley 2020, section 4: the index
    itself Owen-scrambled, so that sets are mutually independent while each keeps its
    stratification at every power of two). The shuffled index is taken XOR the shuffle of
    index 0: a scramble maps [0, 2**k) onto itself, so this is below 2**k for every index
    below 2**k and the Sobol loop runs over log2(spp) bits only, not 32. That changes the
    points by a constant XOR (Sobol points are linear in the index's bits), a digital shift
    that the output scramble (sobol_component) absorbs: the estimator is the same in
    distribution as Burley's. All of it runs in reversed bit order (as Cycles does), which
    saves reversing the index and the coordinates back and forth; the shuffled index is
    reversed back once, to walk its bits from the lowest (sobol_digits)."""
    u, seed = shuffled_index(pix, index_reversed, dset)
    x1, x2, x3 = sobol_digits(u)
    return u, x1, x2, x3, seed


@device
def shuffled_index(pix, index_reversed, dset):
    """(the shuffled sample index, the set's seed) of sobol_set."""
    seed = pcg_hash((pix + (np.uint64(dset) + _K1) * _SET_MUL) & M32)
    t = lk_permutation(index_reversed, seed) ^ lk_permutation(np.uint64(0), seed)
    return reverse_bits(t), seed


@device
def sobol_set_table(pix, index_reversed, dset):
    """sobol_set with the digits from SOBOL_BYTES (the same numbers; the CPU's form)."""
    u, seed = shuffled_index(pix, index_reversed, dset)
    x1, x2, x3 = sobol_digits_table(u)
    return u, x1, x2, x3, seed


@device
def sobol_component(sobol, comp):
    """Uniform float32 in [0, 1): coordinate ``comp`` (0-3) of a sobol_set, Owen-scrambled
    with its own seed."""
    seed = pcg_hash((sobol[4] + np.uint64(comp + 1) * _DIM_MUL) & M32)
    x = reverse_bits(lk_permutation(sobol[comp], seed))
    return np.float32(x >> _S8) * _TO_UNIT


@device
def sample_sobol(pix, index, dim):
    """Dimension ``dim`` of sample ``index`` of the pixel with key ``pix`` (the sobol
    sampler's numbers one at a time; the integrator draws a set at once)."""
    return sobol_component(sobol_set(pix, reverse_bits(np.uint64(index) & M32), dim >> 2),
                           dim & 3)


def _scramble4_py(x0, x1, x2, x3, seed):
    """The four uniform float32 of a Sobol set's coordinates x0-x3 (reversed bit order) and
    its seed: (sobol_component(s, 0), ..., sobol_component(s, 3)) of s = (x0, .., x3, seed)."""
    s = (x0, x1, x2, x3, seed)
    return (sobol_component(s, 0), sobol_component(s, 1), sobol_component(s, 2),
            sobol_component(s, 3))


_V4 = ir.VectorType(_I32, 4)


@intrinsic
def _scramble4_ir(typingctx, x0, x1, x2, x3, seed):
    """_scramble4_py with the four coordinates in one <4 x i32> (the CPU's SIMD form of
    sobol_component's hash, scramble and bit reversal: the same numbers)."""
    args = (x0, x1, x2, x3, seed)
    if not all(isinstance(a, types.Integer) for a in args):
        return None
    sig = types.UniTuple(types.float32, 4)(*args)

    def codegen(context, builder, signature, values):
        return context.make_tuple(builder, signature.return_type,
                                  _scramble_sets_ir(builder, values))
    return sig, codegen


def _to_i32(b, v):
    return b.trunc(v, _I32) if v.type.width > 32 else (
        b.zext(v, _I32) if v.type.width < 32 else v)


def _scramble_sets_ir(b, values):
    """The float32 of whole Sobol sets, scrambled in one vector: ``values`` holds, per set,
    its four coordinates and its seed (x0, x1, x2, x3, seed, x0, ...); lane 4j + c is
    sobol_component of set j's coordinate c."""
    v32 = [_to_i32(b, v) for v in values]
    n = 4 * (len(v32) // 5)
    vec = ir.VectorType(_I32, n)
    x = ir.Constant(vec, ir.Undefined)
    seeds = ir.Constant(vec, ir.Undefined)
    for j in range(n // 4):
        for c in range(4):
            x = b.insert_element(x, v32[5 * j + c], ir.Constant(_I32, 4 * j + c))
            seeds = b.insert_element(seeds, v32[5 * j + 4], ir.Constant(_I32, 4 * j + c))
    return _scramble_ir(b, x, seeds)


def _scramble_ir(b, x, seeds):
    """The float32 lanes of Sobol coordinates x (a vector of i32, four per set) with their
    sets' seeds (each lane its set's seed)."""
    vec = x.type
    n = vec.count
    # per coordinate c the seed pcg_hash(seed + (c + 1) * _DIM_MUL), as sobol_component
    seeds = b.add(seeds, ir.Constant(vec, [_c(((k % 4 + 1) * int(_DIM_MUL)) & 0xFFFFFFFF)
                                           for k in range(n)]))
    # the scalar forms' own IR (_pcg_ir, _lk_ir, _brev_ir) on the lanes
    x = _brev_ir(b, _lk_ir(b, x, _pcg_ir(b, seeds)))
    fvec = ir.VectorType(ir.FloatType(), n)
    f = b.uitofp(b.lshr(x, _c(8, x)), fvec)
    f = b.fmul(f, ir.Constant(fvec, [ir.Constant(ir.FloatType(), float(_TO_UNIT))] * n))
    return [b.extract_element(f, ir.Constant(_I32, k)) for k in range(n)]


overload(_scramble4_py, strict=False)(
    lambda x0, x1, x2, x3, seed: (lambda x0, x1, x2, x3, seed:
                                  _scramble4_ir(x0, x1, x2, x3, seed)))
scramble4 = _scramble4_py


@device
def sobol_floats_table(pix, index_reversed, dset):
    """The four uniform float32 of dimension set ``dset`` (sobol_component of
    sobol_set_table, coordinates 0-3), scrambled four at a time: the CPU's form. It
    scrambles coordinates that a path may not draw (the lens pair, the light set's
    fourth), but in one SIMD stream; with the digit table's one-row path for the first 256
    samples it rendered the sun and the Cornell box ~5 % faster than the scalar scrambles
    (docs/benchmarks.md, 2026-11-28)."""
    u, x1, x2, x3, seed = sobol_set_table(pix, index_reversed, dset)
    return scramble4(u, x1, x2, x3, seed)


def _sobol_pair_py(table, pix, index_reversed, dset):
    """sobol_floats_table of sets dset and dset + 1: eight float32 (``table``: SOBOL_BYTES,
    which the compiled form reads itself)."""
    return (sobol_floats_table(pix, index_reversed, dset)
            + sobol_floats_table(pix, index_reversed, dset + 1))


@intrinsic
def _sobol_pair_ir(typingctx, table, pix, index_reversed, dset):
    """_sobol_pair_py in one stream of vector IR: the two sets' seeds hashed in one
    <4 x i32> (each twice), the four index scrambles of shuffled_index (the index's and
    index 0's, per set) in one Laine-Karras permutation, each set's digits as the XOR of
    four 16-byte table rows (one vector load per byte of the shuffled index: a byte of 0
    reads row 0, zeros), and the eight coordinates scrambled in one <8 x i32>
    (_scramble_sets_ir's arithmetic)."""
    # (the table: SOBOL_BYTES, C-contiguous uint32 rows of four: one 16-byte load each)
    if not (isinstance(table, types.Array) and table.ndim == 3 and table.layout == "C"
            and table.dtype == types.uint32
            and all(isinstance(a, types.Integer) for a in (pix, index_reversed, dset))):
        return None
    sig = types.UniTuple(types.float32, 8)(table, pix, index_reversed, dset)

    def codegen(context, builder, signature, values):
        b = builder
        pix32, index32, dset32 = [_to_i32(b, v) for v in values[1:]]
        lane = [ir.Constant(_I32, k) for k in range(8)]
        key = ir.Constant(_V4, ir.Undefined)
        x = ir.Constant(_V4, ir.Undefined)
        for k in range(4):              # pix + (dset + set + 1) * _SET_MUL, as shuffled_index
            j = k // 2 + 1
            key = b.insert_element(
                key, b.add(pix32, b.mul(b.add(dset32, _c(j)), _c(_SET_MUL))), lane[k])
            x = b.insert_element(x, index32 if k % 2 == 0 else _c(0), lane[k])
        seeds = _pcg_ir(b, key)          # (seed, seed, seed', seed')
        lk = _lk_ir(b, x, seeds)
        ary = context.make_array(signature.args[0])(context, b, values[0])
        sets = []
        for j in range(2):
            u = _brev_ir(b, b.xor(b.extract_element(lk, lane[2 * j]),
                                  b.extract_element(lk, lane[2 * j + 1])))
            digits = None                # (x1, x2, x3, 0): sobol_digits_table
            for k in range(4):
                byte = b.and_(b.lshr(u, _c(8 * k)), _c(255))
                ptr = cgutils.get_item_pointer(
                    context, b, signature.args[0], ary,
                    [context.get_constant(types.intp, k), b.zext(byte, _I64),
                     context.get_constant(types.intp, 0)], wraparound=False)
                row = b.load(b.bitcast(ptr, _V4.as_pointer()), align=4)
                digits = row if digits is None else b.xor(digits, row)
            splat = b.insert_element(ir.Constant(_V4, ir.Undefined), u, lane[0])
            # (u, x1, x2, x3)
            sets.append(b.shuffle_vector(digits, splat, ir.Constant(_V4, [4, 0, 1, 2])))
        v8 = ir.VectorType(_I32, 8)
        xs = b.shuffle_vector(sets[0], sets[1], ir.Constant(v8, list(range(8))))
        seeds8 = b.shuffle_vector(seeds, ir.Constant(_V4, ir.Undefined),
                                  ir.Constant(v8, [0, 0, 0, 0, 2, 2, 2, 2]))
        return context.make_tuple(b, signature.return_type, _scramble_ir(b, xs, seeds8))
    return sig, codegen


overload(_sobol_pair_py, strict=False)(
    lambda table, pix, index_reversed, dset: (lambda table, pix, index_reversed, dset:
                                              _sobol_pair_ir(table, pix, index_reversed,
                                                             dset)))


@device
def sobol_floats_pair(pix, index_reversed, dset):
    """sobol_floats_table of sets dset and dset + 1 (eight float32), the two sets' hashes,
    digits and scrambles in shared vectors: the CPU's form for a bounce's light and BSDF
    sets (layout.DIMS_PER_BOUNCE: two sets), which a bounce opens together."""
    return _sobol_pair_py(SOBOL_BYTES, pix, index_reversed, dset)


def make_sampler(sobol, table=False):
    """The functions of a sampler (closures over the choice, so the other one is not
    compiled):

    - ``start_path(pixel, sample, seed)``: the state of one camera path;
    - ``open_set(state, dim)``: what the draws of dim's set of four share (the sobol
      sampler's Sobol point; nothing for the independent sampler);
    - ``draw(state, dims, dim)``: the uniform float32 of dimension ``dim`` from its opened
      set ``dims``.

    The independent sampler's numbers are ``sample_1d(path_key(pixel, sample, seed), dim)``.
    ``table``: the sobol sampler reads its Sobol digits from SOBOL_BYTES (the CPU kernels:
    four loads, not a loop over the index's bits; the GPU's constant cache would serialise
    them) and scrambles a set's four coordinates at once when it opens the set
    (sobol_floats_table: ``open_set`` returns the four numbers), the same numbers.
    """
    SOBOL = bool(sobol)
    TABLE = bool(table)
    ZERO_SET = (np.uint64(0), np.uint64(0), np.uint64(0), np.uint64(0), np.uint64(0))

    @device
    def start_path(pixel, sample, seed):
        pix = pixel_key(pixel, seed)
        index = np.uint64(sample) & M32
        if SOBOL:
            return pcg_hash((pix + index) & M32), pix, reverse_bits(index)
        return pcg_hash((pix + index) & M32), pix, index

    @device
    def open_set(state, dim):
        if SOBOL:
            if TABLE:
                return sobol_floats_table(state[1], state[2], dim >> 2)
            return sobol_set(state[1], state[2], dim >> 2)
        return ZERO_SET

    @device
    def draw(state, dims, dim):
        if SOBOL:
            if TABLE:
                return dims[dim & 3]
            return sobol_component(dims, dim & 3)
        return sample_1d(state[0], dim)

    return start_path, open_set, draw


def make_pair_opener(sobol, table=False):
    """``open_pair(state, dim)``: (open_set(state, dim), open_set(state, dim + SOBOL_DIMS)) of
    make_sampler(sobol, table), two consecutive sets at once: for the CPU's sobol sampler
    (``table``) one sobol_floats_pair, whose two sets share their vectors (a bounce's light
    and BSDF sets), the same numbers."""
    _, open_set, _ = make_sampler(sobol, table)
    PAIRED = bool(sobol) and bool(table)

    @device
    def open_pair(state, dim):
        if PAIRED:
            f = sobol_floats_pair(state[1], state[2], dim >> 2)
            return (f[0], f[1], f[2], f[3]), (f[4], f[5], f[6], f[7])
        return open_set(state, dim), open_set(state, dim + SOBOL_DIMS)

    return open_pair
