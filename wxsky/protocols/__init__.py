"""Cockpit wire protocols decoded into weather values: NMEA 0183 sentences and CANaerospace
frames. Pure: bytes in, `Decoded` out; the links in `wxsky.inputs` do the I/O."""
