"""Experiments of the paper, reproducible end to end.

Each experiment is a submodule (e.g. :mod:`evomesh.experiments.growing_circle`);
import its function from there. The package does not re-export the functions,
so that no submodule is hidden by a function of the same name.
"""
