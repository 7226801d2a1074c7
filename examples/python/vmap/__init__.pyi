# Type stubs of the vmap module (examples/python/part_*.cpp); tests/python/test_stubs.py
# checks that every name of the module has a stub here and every stub a name.
