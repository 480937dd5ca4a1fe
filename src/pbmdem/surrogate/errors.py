"""Errors of the surrogate's input tables."""

from __future__ import annotations


class CollisionTableError(ValueError):
    """The collision table violates the contract of docs/architecture.md."""
