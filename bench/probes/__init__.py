"""Speed and memory probes: each a command that measures one cost (throughput, latency, peak
memory) of a command or a node; the figures they give are quoted in docs/ with the command."""
