"""Benchmarks behind ``station bench``; timing code lives here, never in unit tests."""
