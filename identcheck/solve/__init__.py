"""Generated numeric solvers that identify joint parameters from exact-model samples."""
from identcheck.solve.revolute21 import BatchResult, Identification, Joint21, identify, solve_batch

__all__ = ["BatchResult", "Identification", "Joint21", "identify", "solve_batch"]
