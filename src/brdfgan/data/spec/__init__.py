"""What a dataset is before any of it is written: its spec and the split of its materials, each
material's maps as the spec paints them (``dataset_spec``), and the seeds and the one torch thread
that make those bytes the same in any process (``determinism``). Shard generation and the
on-the-fly rendered data both read their materials from here."""
