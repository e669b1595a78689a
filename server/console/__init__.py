"""The operator console: plain ES modules and CSS shipped in the package, served at `/`."""
