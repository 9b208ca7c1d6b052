"""Designed controllers and models in other forms: C for the cart's ``control()``, MATLAB files."""
