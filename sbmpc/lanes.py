"""Sixteen float32 lanes as one value in numba code: explicit SIMD for a model's edges.

A node's edges are independent and do the same arithmetic, so a model can compute up
to 16 of them at once, lane b holding edge b. LLVM's auto-vectoriser does not do this
for numba code (the arrays may alias, and a 16-trip loop is unrolled to scalars before
the vectoriser sees it), so :data:`f32x16` is a numba type lowered to LLVM's
``<16 x float>``, with a handful of operations (intrinsics):

* :func:`load` / :func:`store`: 16 consecutive float32 of a contiguous array from index i;
* :func:`splat`: a float32 in every lane;
* :func:`add`, :func:`sub`, :func:`mul`: lane-wise IEEE single-precision arithmetic, each
  result rounded to float32 as scalar float32 code rounds it (no fused multiply-add:
  the instructions carry no fast-math flags, so LLVM may not contract them);
* :func:`less`: the lanes where a < b, as a bit mask (int64, bit b for lane b).

On AVX-512 a value is one register; with AVX2 LLVM splits it into two.
"""
from __future__ import annotations

from llvmlite import ir
from numba import types
from numba.extending import intrinsic, models, register_model

WIDTH = 16
_VEC = ir.VectorType(ir.FloatType(), WIDTH)


class F32x16(types.Type):
    """Numba type of 16 float32 lanes."""

    def __init__(self):
        super().__init__(name="f32x16")


f32x16 = F32x16()


@register_model(F32x16)
class _F32x16Model(models.PrimitiveModel):
    def __init__(self, dmm, fe_type):
        super().__init__(dmm, fe_type, _VEC)


def _float32_array(a) -> bool:
    return isinstance(a, types.Array) and a.dtype == types.float32 and a.layout == "C"


def _lane_pointer(context, builder, aty, arr, i):
    data = context.make_array(aty)(context, builder, arr).data
    return builder.bitcast(builder.gep(data, [i]), _VEC.as_pointer())


@intrinsic
def load(typingctx, a, i):
    """a[i:i + 16] of a C-contiguous float32 array (no bounds check)."""
    if _float32_array(a) and isinstance(i, types.Integer):
        def codegen(context, builder, sig, args):
            return builder.load(_lane_pointer(context, builder, sig.args[0], args[0], args[1]), align=4)
        return f32x16(a, i), codegen


@intrinsic
def store(typingctx, a, i, v):
    """a[i:i + 16] = v (no bounds check)."""
    if _float32_array(a) and isinstance(i, types.Integer) and v == f32x16:
        def codegen(context, builder, sig, args):
            builder.store(args[2], _lane_pointer(context, builder, sig.args[0], args[0], args[1]), align=4)
            return context.get_dummy_value()
        return types.none(a, i, v), codegen


@intrinsic
def splat(typingctx, x):
    """x (a float32) in all 16 lanes."""
    if x == types.float32:
        def codegen(context, builder, sig, args):
            one = builder.insert_element(ir.Constant(_VEC, ir.Undefined), args[0], ir.Constant(ir.IntType(32), 0))
            return builder.shuffle_vector(one, ir.Constant(_VEC, ir.Undefined),
                                          ir.Constant(ir.VectorType(ir.IntType(32), WIDTH), [0] * WIDTH))
        return f32x16(x), codegen


def _binary(op):
    @intrinsic
    def fn(typingctx, a, b):
        if a == f32x16 and b == f32x16:
            def codegen(context, builder, sig, args):
                return getattr(builder, op)(args[0], args[1])
            return f32x16(a, b), codegen
    return fn


add = _binary("fadd")
sub = _binary("fsub")
mul = _binary("fmul")
add.__doc__, sub.__doc__, mul.__doc__ = "a + b, lane-wise.", "a - b, lane-wise.", "a * b, lane-wise."


@intrinsic
def less(typingctx, a, b):
    """Bit mask (int64) of the lanes where a < b (ordered: false for NaN)."""
    if a == f32x16 and b == f32x16:
        def codegen(context, builder, sig, args):
            bits = builder.bitcast(builder.fcmp_ordered("<", args[0], args[1]), ir.IntType(WIDTH))
            return builder.zext(bits, ir.IntType(64))
        return types.int64(a, b), codegen


__all__ = ["WIDTH", "f32x16", "load", "store", "splat", "add", "sub", "mul", "less"]
