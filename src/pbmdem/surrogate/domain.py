"""Recording the surrogate's out-of-domain warnings: never silenced, always counted."""

from __future__ import annotations

import contextlib
import logging
import warnings

from .model import OutOfDomainWarning

log = logging.getLogger(__name__)


@contextlib.contextmanager
def out_of_domain_recorded(where: str, log_each: bool = True):
    """Collect the surrogate's OutOfDomainWarning messages (its own mechanism for inputs outside
    the training range) into the yielded list and log each one; every other warning is passed on
    unchanged. Nothing is silenced: the caller counts and reports what was collected."""
    found: list[str] = []
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", OutOfDomainWarning)
        yield found
    for w in caught:
        if issubclass(w.category, OutOfDomainWarning):
            found.append(str(w.message))
        else:
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    if log_each:
        for message in found:
            log.warning("%s: surrogate out of its training domain: %s", where, message)
