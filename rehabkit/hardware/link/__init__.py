"""The robot link: its wire protocol, each end's socket and session handling, and waiting on a datagram."""
