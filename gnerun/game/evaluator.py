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


class DenseOutputs:
    """A Function with sparse outputs, evaluated as dense numpy arrays: the Function computes the nonzeros alone and
    they are placed into zeros. (A Function whose outputs are densified also writes every structural zero: on the
    condensed KKT function of the paper's game, 4,963 operations against 1,706 and twice the time.)"""

    def __init__(self, f: ca.Function):
        self.function = f
        self._nonzeros = Evaluator(f, dense=False)
        self._places = []  # per output: its shape, and the flat (C-order) position of each nonzero (None: dense)
        for i in range(f.n_out()):
            rows, cols = f.size_out(i)
            sp = f.sparsity_out(i)
            if sp.is_dense():
                self._places.append((rows, cols, None))
                continue
            r, c = sp.get_triplet()  # in the order the nonzeros are stored
            self._places.append((rows, cols, np.asarray(r, dtype=np.intp) * cols + np.asarray(c, dtype=np.intp)))

    def __call__(self, *args: np.ndarray) -> list[np.ndarray]:
        ev = self._nonzeros
        for buf, arg in zip(ev._args, args, strict=True):
            buf[:] = arg
        ev._eval()
        out = []
        for nz, (rows, cols, flat) in zip(ev._res, self._places, strict=True):
            if flat is None:  # stored column by column
                out.append(nz.reshape((rows, cols), order="F").copy())
                continue
            dense = np.zeros(rows * cols)
            dense[flat] = nz
            out.append(dense.reshape(rows, cols))
        return out
