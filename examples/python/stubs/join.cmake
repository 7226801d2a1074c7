# Joins the parts' type stubs (PARTS, ;-separated, in the module's order) into the
# package's __init__.pyi (OUT): one stub file per part in the source, one for editors.
file(WRITE "${OUT}" "# Type stubs of the vmap module, joined from examples/python/stubs/*.pyi at build time.\n"
                    "# tests/python/test_stubs.py checks them against the module in both directions.\n")
foreach(_part IN LISTS PARTS)
  file(READ "${_part}" _text)
  file(APPEND "${OUT}" "\n${_text}")
endforeach()
