"""The client's version (the server's it was released with) and the API it speaks."""

__version__ = "0.1.0"

#: The major version of the HTTP API this client reads (the server's ``x-mocapstore-api``).
API = "1"
