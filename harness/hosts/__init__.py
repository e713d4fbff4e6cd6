"""The FMUs in other FMI hosts: the host matrix (matrix, and the modules its text lists: the host
registry, the runners, the plain fmpy host, docs/hosts.md), the SSP export (ssp), other engines run on
an exported SSP (engines: fmpy.ssp, Ecos; libcosim), and the benchmark against them (bench).  They
import the studies and the core, never the other way."""
