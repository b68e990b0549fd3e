"""Simulated supervisors: populations, schedules, the vectorized engine and crossover designs."""

from .engine import Block, Simulation, Supervisors, crossover, run, simulate

__all__ = ["Block", "Simulation", "Supervisors", "crossover", "run", "simulate"]
