"""Wire-protocol pieces shared by servers, links and clients: OPC UA variants and client connections, the Modbus register codec, MQTT."""
