"""An episode recording's file: rerun `.rrd` entities, styles and layout (`recording_file`) and where
they are drawn (`recording_geometry`); the loop's `recording` fills them."""
