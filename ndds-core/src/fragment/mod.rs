//! Large samples without IO: splitting into pieces, and bounded reassembly. (Being written.)
