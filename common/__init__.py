"""The bottom layer every package may import: errors, units, atomic file writing, the
processing-history schema. It imports none of labtool's packages."""
