"""Device drivers (bytes on the wire) and their firmware-level simulators."""
