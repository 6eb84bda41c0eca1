"""Road builder, the six LANTERN scenario families, warnings, protocol and the frozen suite."""
