"""Standard POMDP files: Cassandra ``.pomdp`` (read and write) and POMDPX (write)."""

from .files import FlatPOMDP, read_pomdp, write_pomdp, write_pomdpx

__all__ = ["FlatPOMDP", "read_pomdp", "write_pomdp", "write_pomdpx"]
