"""Fitting recorded trials: segment poses, joint estimators with uncertainty, excitation checks."""
