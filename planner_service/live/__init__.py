"""The operator's read model of the fleet (pure) and what feeds it from zenoh."""
