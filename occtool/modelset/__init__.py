"""Model sets: one model per robot position of one or more logs, fitted and extracted in parallel.

A model set is a folder holding ``model_NNNN.json`` (one per position, ``NNNN`` the
position's index) and ``index.json`` (the ``occtool-model-set`` format) listing each
position's file, pose, stamp, feature count and the digest of its features.

- :func:`fit_model_set` fits every position of one or more logs. One log writes its set
  into the folder itself; several write one sub-folder each, named after the log's file
  without its format and compression suffixes (``intel-corrected.log.gz`` ->
  ``DIR/intel-corrected/``).
- :func:`read_model_set` reads a set's index back, checked; :func:`save_model_set_index`
  writes it.
- :func:`extract_model_set` extracts the navigation map of every position of one or more
  sets (a folder of sub-folder sets counts as all of them).
- The positions run on an :mod:`occtool.executor` (``jobs`` local processes, or a Dask
  cluster at ``scheduler``). A model's bytes do not depend on where it was fitted: the
  run details (seconds, date, host, ...) are kept apart in its ``run`` object.

Partial results. ``index.json`` is rewritten (atomically) as positions finish, at most
about once a second, with ``"complete": false`` until every position was tried; it then
says ``"complete": true``. A position that fails (bad data, a worker killed) is listed
under ``"failed"`` with its reason and the others are written. An interrupted run
(Ctrl-C, SIGTERM) writes the index of what is finished, still marked incomplete, and
leaves no temporary file. With ``skip_existing`` a later run reuses every model whose
input digest (``training.features_sha256``) and settings digest (``run.settings_sha256``)
match, so a killed run resumes where it stopped.
"""


from __future__ import annotations

from typing import TYPE_CHECKING

from occtool._lazy import lazy_attributes

# public name -> module that defines it, imported on first use (PEP 562): a single fit
# needs estimator_for_log and settings_digest alone, not the model sets' machinery.
_LAZY: dict[str, str] = {
    "Failure": "occtool.modelset._common",
    "ProgressEvent": "occtool.modelset._common",
    "SetSummary": "occtool.modelset._common",
    "find_model_sets": "occtool.modelset._common",
    "log_set_name": "occtool.modelset._common",
    "read_set_state": "occtool.modelset._common",
    "MAX_INDEX_BYTES": "occtool.modelset._index",
    "MODEL_SET_FORMAT": "occtool.modelset._index",
    "read_model_set": "occtool.modelset._index",
    "save_model_set_index": "occtool.modelset._index",
    "extract_model_set": "occtool.modelset._extract",
    "navigation_map_of_file": "occtool.modelset._extract",
    "fit_model_set": "occtool.modelset._fit",
    "estimator_for_log": "occtool.modelset._settings",
    "settings_digest": "occtool.modelset._settings",
}

__all__ = [
    "MAX_INDEX_BYTES", "MODEL_SET_FORMAT", "read_model_set", "save_model_set_index",
    "Failure", "ProgressEvent", "SetSummary", "estimator_for_log", "extract_model_set", "find_model_sets",
    "fit_model_set",
    "log_set_name", "navigation_map_of_file", "read_set_state", "settings_digest",
]

if TYPE_CHECKING:  # pragma: no cover - what the lazy names are, for type checkers and IDEs
    from occtool.modelset._common import (
        Failure,
        ProgressEvent,
        SetSummary,
        find_model_sets,
        log_set_name,
        read_set_state,
    )
    from occtool.modelset._extract import extract_model_set, navigation_map_of_file
    from occtool.modelset._fit import fit_model_set
    from occtool.modelset._index import MAX_INDEX_BYTES, MODEL_SET_FORMAT, read_model_set, save_model_set_index
    from occtool.modelset._settings import estimator_for_log, settings_digest


__getattr__, __dir__ = lazy_attributes(__name__, _LAZY, globals())
