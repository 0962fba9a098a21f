// Anchor translation unit: the torch precompiled header is built with this target.
int hsd_pch_anchor() { return 0; }
