"""The fake shards' fixtures (tests/fake_shards.py)."""

from fake_shards import fake_dataset, shard_writer

__all__ = ["fake_dataset", "shard_writer"]
