"""Evaluation of products against survey data and twin truth: error statistics and accuracy tables."""
