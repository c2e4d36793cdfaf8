"""Sensor models (beam elevations, azimuth steps, range limits; presets and YAML files) and the
check that a scan fits its model."""
