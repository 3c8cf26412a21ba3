"""The robot link's security: keys, authenticated sessions, the handshake."""
