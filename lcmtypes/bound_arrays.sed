# lcm-gen 1.3.1's C++ decoders size an array from its length field before checking that the
# message holds that much: a 100-byte message claiming 10^9 floats makes the receiver allocate
# and zero 4 GB (found by fuzz/fuzz_messages). Every element takes at least one byte, so a
# length above the bytes left (maxlen) is impossible: such a message is refused (decode < 0).
s/^([[:space:]]*)this->([A-Za-z_0-9]+)\.resize\(this->([A-Za-z_0-9]+)\);/\1if (this->\3 < 0 || this->\3 > maxlen) return -1;\n\1this->\2.resize(this->\3);/
