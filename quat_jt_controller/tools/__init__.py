"""Tools around the nodes: MCAP recording, the paper experiment and the 1 kHz benchmark."""
