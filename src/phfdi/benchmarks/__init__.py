"""Public benchmarks: their protocols and our own implementation of their scores (application floor)."""
