"""Presentation: figures, sections, 3D views and the HTML and Markdown reports."""
