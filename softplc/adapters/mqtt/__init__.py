"""The `mqtt:` section's owner: the broker every MQTT user of the runtime connects to (softplc/protocols/mqtt_settings.py).

The users themselves (VDA 5050 master control, the Sparkplug B edge node) are adapters of their
own; each opens its own connection (`softplc.protocols.mqtt.MqttConnection`) with these settings.
"""
