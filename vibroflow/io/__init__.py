"""Round trips with other codes: STL meshes of the tub and the LIGGGHTS deck exporter and dump
importer (vibroflow.io.liggghts)."""
