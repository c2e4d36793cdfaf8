"""The commands a workflow job or the command line runs, between the library and ``cli`` (which
only parses arguments): ``jobs`` (one function per ``lidarfield job``), ``scans`` (``lidarfield
run``, ``explain``, ``field`` and ``register`` on two scan files)."""
