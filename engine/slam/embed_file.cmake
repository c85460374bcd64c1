# Writes OUTPUT, a C++ source defining the bytes of INPUT as `SYMBOL` and its size as
# `SYMBOL_size` (namespace omnirig::slam), so that data ships inside the library.
file(READ "${INPUT}" hex HEX)
string(LENGTH "${hex}" num_hex)
math(EXPR num_bytes "${num_hex} / 2")
string(REGEX REPLACE "([0-9a-f][0-9a-f])" "0x\\1," bytes "${hex}")
string(REGEX REPLACE "(0x..,0x..,0x..,0x..,0x..,0x..,0x..,0x..,0x..,0x..,0x..,0x..,)" "\\1\n"
       bytes "${bytes}")
file(WRITE "${OUTPUT}"
     "// Generated from ${INPUT} by engine/slam/embed_file.cmake.\n"
     "#include <cstddef>\n#include <cstdint>\n"
     "namespace omnirig::slam {\n"
     "extern const std::uint8_t ${SYMBOL}[];\nextern const std::size_t ${SYMBOL}_size;\n"
     "const std::uint8_t ${SYMBOL}[] = {\n${bytes}0};\n"
     "const std::size_t ${SYMBOL}_size = ${num_bytes};\n"
     "}  // namespace omnirig::slam\n")
