"""asyncio helpers every process uses (server, daemons, simulator): standard library only."""
