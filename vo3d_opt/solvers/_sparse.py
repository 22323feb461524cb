"""Dense-pattern CSC matrices shared by the sparse backends (OSQP, Clarabel): every entry is
stored, so problems of one shape share a sparsity pattern and a solver can be updated in place."""

from __future__ import annotations

import functools

import numpy as np
import scipy.sparse as sp


def dense_csc(M: np.ndarray) -> sp.csc_matrix:
    """M as CSC storing every entry, zeros included, column by column."""
    rows, cols = M.shape
    return sp.csc_matrix(
        (M.ravel(order="F"), np.tile(np.arange(rows), cols), np.arange(0, rows * cols + 1, rows)),
        shape=M.shape,
    )


@functools.cache
def triu_index(n: int) -> tuple[np.ndarray, np.ndarray]:
    """(rows, cols) of the upper triangle of an n×n matrix in CSC (column-major) order."""
    cols, rows = np.tril_indices(n)
    return rows, cols


def triu_csc(P: np.ndarray) -> sp.csc_matrix:
    """The upper triangle of P as CSC storing every entry of it."""
    n = P.shape[0]
    rows, cols = triu_index(n)
    indptr = np.concatenate([[0], np.cumsum(np.arange(1, n + 1))])
    return sp.csc_matrix((P[rows, cols], rows, indptr), shape=(n, n))
