"""One module per scan file format, each with ``read_<format>`` (and ``write_<format>``,
``count_<format>`` where the format has them); chosen by :mod:`lidarfield.io`."""
