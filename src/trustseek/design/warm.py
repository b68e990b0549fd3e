"""``python -m trustseek.design.warm``: the design study's compiled kernels are the simulation's, so this
runs :mod:`trustseek.simulation.warm` (``make test`` runs it after the fit's :mod:`trustseek.estimation.warm`)."""

import runpy

if __name__ == "__main__":
    runpy.run_module("trustseek.simulation.warm", run_name="__main__")
