"""Sans-IO FINS protocol core: bytes in, values out. No sockets, no clocks, no anyio."""
