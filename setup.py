"""The compiled extensions, built with Cython by ``pip install`` (everything else is in pyproject.toml).

The loops are compiled ahead of time, so no process compiles them at run time.
``-ffp-contract=off``: no fused multiply-add, so the compiled loops give the numpy references'
numbers to the last bit on every CPU.
"""

import multiprocessing
import os

from Cython.Build import cythonize
from setuptools import Extension, setup

FLAGS = ["-O2", "-ffp-contract=off"]
DIRECTIVES = {"language_level": 3, "boundscheck": False, "wraparound": False, "cdivision": True, "initializedcheck": False}

EXTENSIONS = [
    Extension(
        "trustseek.estimation.forward_backward", ["src/trustseek/estimation/forward_backward.pyx"], extra_compile_args=FLAGS
    ),
    Extension("trustseek.estimation.stick_maps", ["src/trustseek/estimation/stick_maps.pyx"], extra_compile_args=FLAGS),
    Extension("trustseek.estimation.compiled_steps", ["src/trustseek/estimation/compiled_steps.pyx"], extra_compile_args=FLAGS),
    Extension("trustseek.estimation.compiled_em", ["src/trustseek/estimation/compiled_em.pyx"], extra_compile_args=FLAGS),
    Extension("trustseek.solvers.type_bounds", ["src/trustseek/solvers/type_bounds.pyx"], extra_compile_args=FLAGS),
    Extension("trustseek.simulation.kernels", ["src/trustseek/simulation/kernels.pyx"], extra_compile_args=FLAGS),
]

# Cython and the C compiler on every core: the same binaries in half the time.  Cython's workers are
# processes, forked (a start method that spawns would run this file again in each): one elsewhere
JOBS = min(os.cpu_count() or 1, len(EXTENSIONS))
CYTHON_JOBS = JOBS if multiprocessing.get_start_method() == "fork" else 0

setup(
    ext_modules=cythonize(EXTENSIONS, compiler_directives=DIRECTIVES, build_dir="build/cython", nthreads=CYTHON_JOBS),
    options={"build_ext": {"parallel": JOBS}},
)
