"""What training and evaluation read: the shard DataModule (``datamodule``) and photos rendered
on the fly from a material bank (``rendered``)."""
