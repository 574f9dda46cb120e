"""Checks of the station itself: on a certified master part (docs/monitor.md)."""
