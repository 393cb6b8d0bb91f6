"""What the station's Modbus devices share: URL parsing (:mod:`station.modbus.modbus_url`), the pymodbus
client transport with bounded retries (:mod:`station.modbus.client`) and the heartbeat thread
(:mod:`station.modbus.heartbeat`). The rig and the climate chamber build on it; it imports only
the kernel."""
