"""What training and evaluation read: the shard DataModule (``datamodule``), its crops and turns
(``augment``), and photos rendered on the fly from a material bank (``rendered``)."""
