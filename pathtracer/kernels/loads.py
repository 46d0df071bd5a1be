"""Four neighbouring array elements in one load.

A BVH node is 12 floats of boxes and 4 ints of children. Numba loads every element on its
own (it cannot prove the alignment that a vector load needs), so a node visit issued 16
load instructions on the GPU. ``load4(a, i, j)`` reads ``a[i, j:j+4]`` of a 2-D array, and
``load4_texel(a, i, j)`` ``a[i, j, 0:4]`` of a 3-D one (the environment map's texels), as
one 128-bit load (``ld.v4``) in compiled code; interpreted, they are four plain reads.

Alignment: the GPU needs the 16 bytes 16-byte aligned: rows (or texels) of a multiple of 16
bytes, j a multiple of 4 in a 2-D array, and a base address aligned to 16, which every
array that the CUDA backend copies to the device has (``cuda.to_device`` allocates, aligned
to 256 bytes; checked in ``backends.cuda``). On the CPU the load is marked 4-byte aligned
(x86 loads any alignment), so arrays from anywhere work.

``prefetch(a, i, j)`` asks the CPU to bring a[i, j]'s cache line in early (the sky's texels
of an escaped ray whose lookup comes a few paths later: drivers.deferred).
"""
from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic, overload


def load4(a, i, j):
    """(a[i, j], a[i, j + 1], a[i, j + 2], a[i, j + 3]) of a 2-D C-contiguous array."""
    return a[i, j], a[i, j + 1], a[i, j + 2], a[i, j + 3]


def load4_texel(a, i, j):
    """(a[i, j, 0], a[i, j, 1], a[i, j, 2], a[i, j, 3]) of a 3-D C-contiguous array whose
    last axis has 4 elements."""
    return a[i, j, 0], a[i, j, 1], a[i, j, 2], a[i, j, 3]


def prefetch(a, i, j):
    """A hint that a[i, j] (a 2-D C-contiguous array; a[i, j, 0] of a 3-D one) will be read
    soon: on the CPU one prefetch instruction for its cache line (LLVM's ``llvm.prefetch``),
    nothing on the GPU and interpreted. The address is not checked: a prefetch never
    faults."""
    return None


def vector_alignment(context):
    """The alignment to mark a 16-byte vector load with: 16 on the GPU (which needs it for
    one ``ld.v4``; see the alignment rules above), 4 on the CPU (x86 loads any)."""
    return 16 if "cuda" in type(context).__module__ else 4


def _load4_typer(ndim):
    def typer(typingctx, a, i, j):
        if not (isinstance(a, types.Array) and a.ndim == ndim and a.layout == "C"
                and a.dtype in (types.float32, types.int32)
                and isinstance(i, types.Integer) and isinstance(j, types.Integer)):
            return None
        return types.UniTuple(a.dtype, 4)(a, i, j), _load4_codegen
    return typer


def _item_pointer(context, builder, signature, args):
    """The address of a[i, j] (a[i, j, 0] of a 3-D array), unchecked."""
    aryty, ity, jty = signature.args
    ary = context.make_array(aryty)(context, builder, args[0])
    inds = [context.cast(builder, args[1], ity, types.intp),
            context.cast(builder, args[2], jty, types.intp)]
    inds += [context.get_constant(types.intp, 0)] * (aryty.ndim - 2)
    return cgutils.get_item_pointer(context, builder, aryty, ary, inds, wraparound=False)


def _load4_codegen(context, builder, signature, args):
    """Four elements from a[i, j] (2-D: along the row; 3-D: along the last axis)."""
    aryty = signature.args[0]
    ptr = _item_pointer(context, builder, signature, args)
    vty = ir.VectorType(context.get_data_type(aryty.dtype), 4)
    v = builder.load(builder.bitcast(ptr, vty.as_pointer()), align=vector_alignment(context))
    vals = [builder.extract_element(v, ir.Constant(ir.IntType(32), k)) for k in range(4)]
    return context.make_tuple(builder, signature.return_type, vals)


@intrinsic
def _prefetch_ir(typingctx, a, i, j):
    if not (isinstance(a, types.Array) and a.ndim in (2, 3) and a.layout == "C"
            and isinstance(i, types.Integer) and isinstance(j, types.Integer)):
        return None

    def codegen(context, builder, signature, args):
        if "cuda" in type(context).__module__:
            return context.get_dummy_value()
        i8p = ir.IntType(8).as_pointer()
        ptr = builder.bitcast(_item_pointer(context, builder, signature, args), i8p)
        i32 = ir.IntType(32)
        fn = cgutils.get_or_insert_function(
            builder.module, ir.FunctionType(ir.VoidType(), [i8p, i32, i32, i32]),
            "llvm.prefetch.p0")
        # (read, keep in all cache levels, data cache)
        builder.call(fn, [ptr, ir.Constant(i32, 0), ir.Constant(i32, 3), ir.Constant(i32, 1)])
        return context.get_dummy_value()
    return types.none(a, i, j), codegen


_load4_ir = intrinsic(_load4_typer(2))
_load4_texel_ir = intrinsic(_load4_typer(3))
overload(load4, strict=False)(lambda a, i, j: (lambda a, i, j: _load4_ir(a, i, j)))
overload(prefetch, strict=False)(lambda a, i, j: (lambda a, i, j: _prefetch_ir(a, i, j)))
overload(load4_texel, strict=False)(
    lambda a, i, j: (lambda a, i, j: _load4_texel_ir(a, i, j)))
