"""The station watches itself: control charts over its own evidence (docs/monitor.md)."""
