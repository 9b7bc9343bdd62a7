"""Experiments on the closed loop: scenarios, recorded sessions, comparisons, metrics,
plots and the step-time benchmark."""
