"""THE PAPERS: the CGS, Rice and NEES-UCSD programmes and their published numbers. The only place that names a table."""
