"""Thorlabs APT stage (Z8 actuator): the wire protocol (:mod:`.protocol`), the driver
(:mod:`.stage`) and a firmware-level simulator on a real pseudo-terminal (:mod:`.sim`).
"""
