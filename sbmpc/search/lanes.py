"""Sixteen float lanes as one value in numba code: explicit SIMD for a model's edges.

A node's edges are independent and do the same arithmetic, so a model can compute up
to 16 of them at once, lane b holding edge b. LLVM's auto-vectoriser does not do this
for numba code (the arrays may alias, and a 16-trip loop is unrolled to scalars before
the vectoriser sees it), so :data:`f32x16` and :data:`f64x16` are numba types lowered to
LLVM's ``<16 x float>`` and ``<16 x double>``, with a handful of operations
(intrinsics):

* :func:`load` / :func:`store`: 16 consecutive elements of a contiguous float32 or
  float64 array from index i (no bounds check);
* :func:`splat`: a float32 or float64 in every lane;
* :func:`widen`: float32 lanes to float64 (exact);
* :func:`add`, :func:`sub`, :func:`mul`, :func:`div`, :func:`sqrt`, :func:`absolute`,
  :func:`floor`, :func:`copysign`: lane-wise IEEE arithmetic, each result rounded as the
  scalar code of the same precision rounds it (no fused multiply-add: the instructions
  carry no fast-math flags, so LLVM may not contract them);
* :func:`less`: the lanes where a < b, as a bit mask (int64, bit b for lane b).

On AVX-512 a float32 value is one register; with AVX2 LLVM splits it into two.
"""
from __future__ import annotations

from llvmlite import ir
from numba import types
from numba.extending import intrinsic, models, register_model

WIDTH = 16


class Lanes(types.Type):
    """Numba type of 16 lanes of ``dtype`` (float32 or float64)."""

    def __init__(self, dtype):
        self.dtype = dtype
        super().__init__(name=f"{dtype}x{WIDTH}")


f32x16 = Lanes(types.float32)
f64x16 = Lanes(types.float64)
_OF = {types.float32: f32x16, types.float64: f64x16}


def _vector(lanes: Lanes) -> ir.VectorType:
    return ir.VectorType(ir.FloatType() if lanes.dtype == types.float32 else ir.DoubleType(), WIDTH)


@register_model(Lanes)
class _LanesModel(models.PrimitiveModel):
    def __init__(self, dmm, fe_type):
        super().__init__(dmm, fe_type, _vector(fe_type))


def _lanes_of_array(a):
    if isinstance(a, types.Array) and a.layout == "C" and a.dtype in _OF:
        return _OF[a.dtype]
    return None


def _lane_pointer(context, builder, aty, arr, i):
    data = context.make_array(aty)(context, builder, arr).data
    return builder.bitcast(builder.gep(data, [i]), _vector(_OF[aty.dtype]).as_pointer())


@intrinsic
def load(typingctx, a, i):
    """a[i:i + 16] of a C-contiguous float32 or float64 array (no bounds check)."""
    t = _lanes_of_array(a)
    if t is not None and isinstance(i, types.Integer):
        def codegen(context, builder, sig, args):
            return builder.load(_lane_pointer(context, builder, sig.args[0], args[0], args[1]),
                                align=sig.args[0].dtype.bitwidth // 8)
        return t(a, i), codegen


@intrinsic
def store(typingctx, a, i, v):
    """a[i:i + 16] = v (no bounds check)."""
    if _lanes_of_array(a) == v and isinstance(i, types.Integer):
        def codegen(context, builder, sig, args):
            builder.store(args[2], _lane_pointer(context, builder, sig.args[0], args[0], args[1]),
                          align=sig.args[0].dtype.bitwidth // 8)
            return context.get_dummy_value()
        return types.none(a, i, v), codegen


@intrinsic
def splat(typingctx, x):
    """x (a float32 or float64) in all 16 lanes."""
    if x in _OF:
        t = _OF[x]

        def codegen(context, builder, sig, args):
            vec = _vector(t)
            one = builder.insert_element(ir.Constant(vec, ir.Undefined), args[0], ir.Constant(ir.IntType(32), 0))
            return builder.shuffle_vector(one, ir.Constant(vec, ir.Undefined),
                                          ir.Constant(ir.VectorType(ir.IntType(32), WIDTH), [0] * WIDTH))
        return t(x), codegen


@intrinsic
def widen(typingctx, v):
    """float32 lanes as float64 lanes (exact)."""
    if v == f32x16:
        def codegen(context, builder, sig, args):
            return builder.fpext(args[0], _vector(f64x16))
        return f64x16(v), codegen


def _call(builder, name, t, args):
    """Call LLVM's intrinsic ``llvm.<name>`` on lanes of type t."""
    vec = _vector(t)
    suffix = f"v{WIDTH}f{t.dtype.bitwidth}"          # llvmlite names no vector type itself
    fnty = ir.FunctionType(vec, [vec] * len(args))
    f = builder.module.globals.get(f"llvm.{name}.{suffix}") or ir.Function(builder.module, fnty,
                                                                           f"llvm.{name}.{suffix}")
    return builder.call(f, args)


def _binary(emit, doc):
    """An operation of two lanes of one type; ``emit(builder, type, args)`` builds it."""
    @intrinsic
    def fn(typingctx, a, b):
        if isinstance(a, Lanes) and a == b:
            def codegen(context, builder, sig, args):
                return emit(builder, a, args)
            return a(a, b), codegen
    fn.__doc__ = doc
    return fn


def _unary(name, doc):
    """LLVM's intrinsic ``llvm.<name>`` on one lanes value."""
    @intrinsic
    def fn(typingctx, a):
        if isinstance(a, Lanes):
            def codegen(context, builder, sig, args):
                return _call(builder, name, a, args)
            return a(a), codegen
    fn.__doc__ = doc
    return fn


add = _binary(lambda b, t, args: b.fadd(*args), "a + b, lane-wise.")
sub = _binary(lambda b, t, args: b.fsub(*args), "a - b, lane-wise.")
mul = _binary(lambda b, t, args: b.fmul(*args), "a * b, lane-wise.")
div = _binary(lambda b, t, args: b.fdiv(*args), "a / b, lane-wise.")
copysign = _binary(lambda b, t, args: _call(b, "copysign", t, args), "|a| with the sign of b, lane-wise.")
sqrt = _unary("sqrt", "Square root, lane-wise (correctly rounded, as math.sqrt).")
absolute = _unary("fabs", "|a|, lane-wise.")
floor = _unary("floor", "floor(a), lane-wise.")


@intrinsic
def less(typingctx, a, b):
    """Bit mask (int64) of the lanes where a < b (ordered: false for NaN)."""
    if isinstance(a, Lanes) and a == b:
        def codegen(context, builder, sig, args):
            bits = builder.bitcast(builder.fcmp_ordered("<", args[0], args[1]), ir.IntType(WIDTH))
            return builder.zext(bits, ir.IntType(64))
        return types.int64(a, b), codegen


__all__ = ["WIDTH", "Lanes", "f32x16", "f64x16", "load", "store", "splat", "widen", "add", "sub", "mul", "div",
           "sqrt", "absolute", "floor", "copysign", "less"]
