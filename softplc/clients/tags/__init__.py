"""`softplc read`, `write`, `watch`, `forces`, `force`, `unforce`: a running plant's tags from the command line."""
