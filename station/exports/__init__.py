"""Documents the domain writes for systems outside the station.

``qif``: an inspection record as a QIF 3.0 results document, for the plant's quality
systems. The REST route ``GET /api/v1/inspections/{id}/qif`` and the CLI
``station results qif ID`` both serve it from here, so the two give the same bytes.
"""

from station.exports.qif import QIF_NS, QIF_VERSION, finished_qif_bytes, inspection_status, qif_bytes, qif_document

__all__ = ["QIF_NS", "QIF_VERSION", "finished_qif_bytes", "inspection_status", "qif_bytes", "qif_document"]
