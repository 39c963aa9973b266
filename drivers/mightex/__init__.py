"""Mightex MCE-B013-U USB camera: the wire protocol (:mod:`.protocol`), the pyusb driver
(:mod:`.camera`), the simulator as a pyusb backend (:mod:`.sim`, :mod:`.sim_usb`,
:mod:`.sim_sensor`) and the fault-injection soak (:mod:`.soak`).
"""
