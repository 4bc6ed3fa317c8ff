"""`softplc latency`: the thesis's case IV handshake measured over OPC UA and Modbus TCP."""
