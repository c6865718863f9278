"""The discrepancy workflow: where the rigid-joint model and the measured markers disagree, which named
effect explains it, and how much of the gap modelling that effect closes (``identcheck diagnose``)."""
