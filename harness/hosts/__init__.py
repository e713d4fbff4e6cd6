"""The FMUs in other FMI hosts: the host matrix (matrix), the SSP export (ssp), other engines run on
an exported SSP (engines: fmpy.ssp, Ecos; libcosim), and the benchmark against them (bench).  They
import the studies and the core, never the other way."""
