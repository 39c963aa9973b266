"""Commands that talk to the devices: ``devices``, ``snap``, ``led``, ``stage``, ``simulate``,
``doctor`` (guided bring-up) and the camera soak."""
