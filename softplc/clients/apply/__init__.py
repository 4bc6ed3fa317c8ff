"""`softplc apply`: online change of a running plant."""
