"""Mightex SLC LED controller: the wire protocol (:mod:`.protocol`), the pyserial driver
(:mod:`.controller`) and a simulator on a real pseudo-terminal (:mod:`.sim`).
"""
