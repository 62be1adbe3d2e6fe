"""Reading the solve report back from an edits layer as a :class:`~mocapedit.model.report.StoredReport`,
with the layer's provenance and units, as ``mocapedit report`` prints it. The format itself
(keys, errors) is :mod:`mocapedit.usd.edits_format`'s.
"""
from __future__ import annotations

from mocapedit.model.report import Report, StoredReport
from mocapedit.usd import edits_format


def read_report(path_or_layer) -> StoredReport:
    """Reads the report from an edits layer, or from the edits layer a stage sub-layers.

    Raises:
      MocapEditError: the file cannot be read or holds no mocapedit report.
    """
    found = edits_format.read_report(path_or_layer)
    return StoredReport(
        file=found["file"], report=Report.from_dict(found["report"]), version=found["version"],
        inputs=found["inputs"], content_hash=found["contentHash"],
        meters_per_unit=found["metersPerUnit"], up_axis=found["upAxis"])
