"""The CAN bus as the host sees it: the python-can buses, the PDO layout and its arithmetic, the maps written
into nodes, and what validate checks."""
