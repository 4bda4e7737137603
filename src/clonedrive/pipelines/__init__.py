"""The pipelines that run the other parts end to end: ``demo`` (from nothing to a measured,
written-up driving model) and ``dagger`` (DAgger's iterations)."""
