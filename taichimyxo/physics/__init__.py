"""The model: the state, the force terms, the integrators, the neighbour lists, the starts and the stability limits
(docs/model.md)."""
