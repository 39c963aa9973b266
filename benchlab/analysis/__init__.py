"""Pure analysis functions: arrays in, numbers out. No devices, no files."""
