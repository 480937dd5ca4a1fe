"""The response surface's polynomial terms at prediction (``families.ResponseSurface``): the
pipeline's own arithmetic on its fitted attributes, a term of at most two factors as their one
product, and the terms shared by outputs (and, inside :func:`shared_terms`, by models) of equal
scalers and powers at equal features. The same numbers as the pipelines' ``predict``
(tests/test_surrogate_families.py); split from ``families`` to keep it one concept per module.
"""

from __future__ import annotations

import weakref
from contextlib import contextmanager
from contextvars import ContextVar

import numpy as np
from sklearn.pipeline import Pipeline

#: The polynomial terms shared by the predictions inside :func:`shared_terms` (None: outside)
SHARED: ContextVar[dict | None] = ContextVar("pbmdem_shared_terms", default=None)


@contextmanager
def shared_terms():
    """Inside: the response surfaces' predictions share their polynomial terms at equal X (the
    bytes of X, the scalers and the powers; the same numbers), e.g. the wall models' frequency and
    impact-speed law on the same classes (``CollisionSurrogate.impacts``). The terms are dropped
    on leaving."""
    token = SHARED.set({})
    try:
        yield
    finally:
        SHARED.reset(token)


#: Per fitted response-surface pipeline: its scalers' fitted arrays (a pipeline fitted again has
#: new ones: computed again), its polynomial's ``powers_`` (terms, features; a property that
#: recomputes every combination at each access, which cost half of a prediction), their
#: :func:`two_factors` and the bytes of everything its terms depend on besides X (scalers,
#: powers). Weak keys: a pipeline that is gone leaves no entry.
POWERS = weakref.WeakKeyDictionary()


def two_factors(powers: np.ndarray):
    """(feature, power) of the first and the second feature of nonzero power of every term
    (feature 0 at power 0, an exact 1, for a term of one feature), or None if a term has three or
    more (degree 3 and up): a term of at most two factors is their one product whatever the order
    of the exact 1s around them, so it equals the product over all features (:func:`term_products`)."""
    rows = [np.flatnonzero(row) for row in powers]
    if any(r.size > 2 for r in rows):
        return None
    f1 = np.array([r[0] for r in rows])
    f2 = np.array([r[1] if r.size > 1 else 0 for r in rows])
    return f1, powers[np.arange(len(rows)), f1], f2, np.where(f2 > 0, powers[np.arange(len(rows)), f2], 0)


def term_products(table: np.ndarray, powers: np.ndarray, factors) -> np.ndarray:
    """(n, terms): the product over the features of ``table[:, f, powers[t, f]]`` (``table``: every
    power of every feature, (n, features, degree + 1)) for every term t: with ``factors``
    (:func:`two_factors`) the product of its two factors, else over all features in their order."""
    if factors is not None:
        f1, p1, f2, p2 = factors
        # C order, as the product below (the index gives (n, terms) in Fortran order; the terms'
        # matrix products would then sum in another order)
        return np.ascontiguousarray(table[:, f1, p1] * table[:, f2, p2])
    # contiguous so that the product runs over the features in their order (as the loop it replaced)
    return np.prod(np.ascontiguousarray(table[:, np.arange(powers.shape[1]), powers]), axis=2)


def polynomial_terms(pipeline: Pipeline, X: np.ndarray, shared: dict | None = None) -> np.ndarray:
    """The standardised polynomial terms of a fitted :meth:`~.families.ResponseSurface._pipeline_of` at X:
    scale, the products of the powers ``poly.powers_`` (features multiplied in their order: a
    power 0 contributes an exact 1), scale the terms. ``shared`` (one prediction's, at one X):
    terms already computed by a pipeline of equal scalers and powers are taken from it (the same
    numbers; the PBM's impact-speed law has three outputs, mostly of one degree; inside
    :func:`shared_terms` also other models' at an equal X)."""
    (_, scale), (_, poly), (_, scale_terms), _ = pipeline.steps  # by position: naming a step costs a lookup
    fitted = (scale.mean_, scale.scale_, scale_terms.mean_, scale_terms.scale_)
    known = POWERS.get(pipeline)
    if known is None or any(a is not b for a, b in zip(known[0], fitted, strict=True)):  # new, or refitted
        powers = poly.powers_
        parts = (*fitted[:2], powers, *fitted[2:])
        key = b"|".join(f"{a.dtype.str}{a.shape}".encode() + a.tobytes() for a in map(np.ascontiguousarray, parts))
        known = POWERS[pipeline] = (fitted, powers, two_factors(powers), key)
    _, powers, factors, key = known
    if shared is not None:
        key = (key, X.shape, X.dtype.str, X.tobytes())
        if key in shared:
            return shared[key]
    x = (X - scale.mean_) / scale.scale_
    # every power of every feature once, (n, features, degree + 1), then each term's factors by index
    table = x[:, :, None] ** np.arange(powers.max() + 1)
    terms = (term_products(table, powers, factors) - scale_terms.mean_) / scale_terms.scale_
    if shared is not None:
        shared[key] = terms
    return terms
