"""The wire protocol between the glasses and the cloud (msgpack messages; see README.md)."""
