"""Tactile Thing Descriptions: vocabulary, builder, validation."""
