"""Test campaigns: a plan of operating points acquired, processed and compared; one verdict across them."""
