"""The inspection cycle: the compensated bore scan plan and the inspection service."""
