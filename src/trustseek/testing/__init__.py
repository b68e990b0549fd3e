"""Throwaway servers for tests, benchmarks and notebooks: the experiment server on a free
loopback port and a temporary PostgreSQL cluster."""
