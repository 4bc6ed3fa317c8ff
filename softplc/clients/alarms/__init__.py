"""`softplc alarms`: list, acknowledge, shelve and comment alarms of a running plant; read its journal."""
