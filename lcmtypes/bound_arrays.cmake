# Run after lcm-gen on one generated C++ header (cmake -DHEADER=... -P bound_arrays.cmake).
# LCM 1.3.1's generated decode sizes a variable-length array from its length field
# before it checks that the buffer holds that many elements: a datagram of a few
# dozen bytes with num_axes = 2^31-1 made the receiver allocate (and zero) up to
# 16 GB, and keep it (the bus decodes into one message object per subscription).
# Every element takes at least one byte, so a length beyond the bytes left (or a
# negative one) is refused before the resize: decode returns -1, a decode failure.
# A string's length (its bytes and the NUL) must be at least 1: the generated code
# assigned len - 1 bytes, a signed overflow for INT32_MIN and a length_error for 0.
file(READ "${HEADER}" text)
string(REGEX REPLACE "this->([A-Za-z0-9_]+)\\.resize\\(this->([A-Za-z0-9_]+)\\);"
       "if (this->\\2 < 0 || this->\\2 > maxlen - pos) return -1; this->\\1.resize(this->\\2);" text "${text}")
string(REGEX REPLACE "if\\((__[A-Za-z0-9_]+) > maxlen - pos\\) return -1;"
       "if(\\1 < 1 || \\1 > maxlen - pos) return -1;" text "${text}")
file(WRITE "${HEADER}" "${text}")
