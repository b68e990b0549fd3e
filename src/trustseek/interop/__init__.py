"""Standard POMDP files: Cassandra ``.pomdp`` (read and write) and POMDPX (write)."""

from .files import PomdpFileError, export_assistance, read_pomdp, write_pomdp, write_pomdpx

__all__ = ["PomdpFileError", "export_assistance", "read_pomdp", "write_pomdp", "write_pomdpx"]
