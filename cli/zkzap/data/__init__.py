"""Package data: the example throttle schedule (``zk profile --example``)."""
