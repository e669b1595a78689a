"""Live video: one viewer API (WHEP) over two media paths, the embedded aiortc relay and Janus."""
