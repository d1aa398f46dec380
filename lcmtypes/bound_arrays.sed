# lcm-gen 1.3.1's C++ decoders size an array from its length field before checking that the
# message holds that much: a 100-byte message claiming 10^9 floats makes the receiver allocate
# and zero 4 GB (found by fuzz/fuzz_messages). Every element takes at least one byte, so a
# length above the bytes left (maxlen) is impossible: such a message is refused (decode < 0).
s/^([[:space:]]*)this->([A-Za-z_0-9]+)\.resize\(this->([A-Za-z_0-9]+)\);/\1if (this->\3 < 0 || this->\3 > maxlen) return -1;\n\1this->\2.resize(this->\3);/
# Strings: a length field of 0 or less (a valid string has at least its terminating NUL) made
# the decoder throw std::length_error or overflow (found by fuzz/fuzz_messages): refused.
s/if\(__([A-Za-z_0-9]+)_len__ > maxlen - pos\) return -1;/if(__\1_len__ > maxlen - pos || __\1_len__ < 1) return -1;/
s/if\(__elem_len > maxlen - pos\) return -1;/if(__elem_len > maxlen - pos || __elem_len < 1) return -1;/
