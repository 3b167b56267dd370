"""The interfaces: the Python API, the command line and the throughput benchmark command."""
