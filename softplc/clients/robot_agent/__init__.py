"""`softplc robot-agent`: a robot's driver on its own computer, connected to the plant over OPC UA."""
