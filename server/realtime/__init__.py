"""The realtime hub: asset and operator WebSockets, fan-out and command routing across processes."""
