"""Launching a compiled kernel without Taichi's per-call Python work (docs/performance.md, "The step kernel").

Taichi's Python wrapper spends about 70 µs of CPU on every kernel call (argument checks, the template-key lookup,
the data-oriented owner's attribute hooks): more than a whole step of a small system, and a tenth or more of a
half- or quarter-scale run's step. `direct(kernel)` takes a bound kernel of a data-oriented object whose only
template argument is the object itself and whose other arguments are scalars, and returns a function with the
kernel's signature: its first call goes through Taichi (which compiles the kernel or loads it from the cache), later
calls launch that same compiled kernel with a fresh launch context. Same machine code, same arguments, so the same
results bit for bit (tests/test_kernel_call.py). A kernel outside that shape, or a Taichi without these internals,
gets Taichi's own call.
"""
from __future__ import annotations


def direct(kernel):
    """`kernel` (e.g. `self._step` of a @ti.data_oriented object), called directly after its first call."""
    try:
        return _Direct(kernel)
    except (AttributeError, ImportError, TypeError, ValueError):
        return kernel


class _Direct:
    def __init__(self, kernel):
        from taichi.lang.util import cook_dtype
        from taichi.types import primitive_types
        from taichi.types.annotations import template
        from taichi.types.utils import is_signed

        self._kernel = kernel
        self._primal, self._owner = kernel._primal, kernel._kernel_owner
        if kernel._is_staticmethod:
            raise TypeError("a static kernel has no owner")
        setters = []
        for i, arg in enumerate(self._primal.arguments):
            a = arg.annotation
            if isinstance(a, template):
                if i != 0:
                    raise TypeError("only the owner may be a template argument")
            elif a in primitive_types.real_types:
                setters.append(("set_arg_float", float))
            elif a in primitive_types.integer_types and is_signed(cook_dtype(a)):
                setters.append(("set_arg_int", int))
            else:
                raise TypeError(f"argument {arg.name}: not a scalar")
        if not isinstance(self._primal.arguments[0].annotation, template):
            raise TypeError("the owner is not the first argument")
        ret = self._primal.return_type
        ret = tuple(ret) if ret is not None else ()
        if len(ret) > 1:
            raise TypeError("more than one return value")
        self._get = None
        if ret:
            if ret[0] in primitive_types.real_types:
                self._get = "get_struct_ret_float"
            elif ret[0] in primitive_types.integer_types and is_signed(cook_dtype(ret[0])):
                self._get = "get_struct_ret_int"
            else:
                raise TypeError("the return value is not a signed scalar")
        self._setters = setters
        self._launch = None

    def _prepare(self, args) -> None:
        from taichi.lang import impl
        key = self._primal.ensure_compiled(self._owner, *args)
        t_kernel = self._primal.compiled_kernels[key]
        runtime = impl.get_runtime()
        prog = runtime.prog
        compiled = prog.compile_kernel(prog.config(), prog.get_device_caps(), t_kernel)
        # prog.synchronize, not runtime.sync, which checks every field builder again on each call: the first call
        # materialized them
        make, launch, sync = t_kernel.make_launch_context, prog.launch_kernel, prog.synchronize
        setters, get = self._setters, self._get

        def call(*a):
            ctx = make()
            for i, (s, cast) in enumerate(setters):
                getattr(ctx, s)((i,), cast(a[i]))
            launch(compiled, ctx)
            if get is None:
                return None
            sync()
            return getattr(ctx, get)((0,))
        self._launch = call

    def __call__(self, *args):
        if self._launch is None:
            out = self._kernel(*args)          # Taichi's own call: compiles (or loads) the kernel, checks the arguments
            self._prepare(args)
            return out
        return self._launch(*args)
