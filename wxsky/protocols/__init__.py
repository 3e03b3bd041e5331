"""Wire protocols, pure bytes in and values out; the links and sockets in `wxsky.inputs` do
the I/O. Cockpit: NMEA 0183 sentences and CANaerospace frames into `Decoded` weather values.
Hosts: CIGI 3.3 datagrams into checked packets, and packets into datagrams."""
