"""MCAP: the file reader, split-file sets, the record scanner, the chunked writer and channel QoS."""
