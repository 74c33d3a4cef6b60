"""A CasADi Function evaluated into preallocated numpy buffers."""

from __future__ import annotations

import casadi as ca
import numpy as np


class Evaluator:
    """A CasADi Function evaluated into preallocated numpy buffers (no per-call DM conversions).

    Calling it copies the arguments into the input buffers, evaluates, and returns fresh numpy arrays
    shaped like the Function's (dense) outputs; with ``dense=False``, the outputs' nonzeros as they are
    stored (column by column).
    """

    def __init__(self, f: ca.Function, dense: bool = True):
        self.function = f
        self._args = [np.zeros(f.nnz_in(i)) for i in range(f.n_in())]
        self._res = [np.zeros(f.nnz_out(i)) for i in range(f.n_out())]
        self._shapes = [f.size_out(i) if dense else (f.nnz_out(i),) for i in range(f.n_out())]
        self._buffer, self._eval = f.buffer()
        for i, arr in enumerate(self._args):
            self._buffer.set_arg(i, memoryview(arr))
        for i, arr in enumerate(self._res):
            self._buffer.set_res(i, memoryview(arr))

    def __call__(self, *args: np.ndarray) -> list[np.ndarray]:
        for buf, arg in zip(self._args, args, strict=True):
            buf[:] = arg
        self._eval()
        # CasADi stores dense matrices column by column
        return [r.reshape(shape, order="F").copy() for r, shape in zip(self._res, self._shapes, strict=True)]
