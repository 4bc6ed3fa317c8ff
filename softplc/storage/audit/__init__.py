"""The audit trail's store: its entries, tables, searches and the `audit:` section's storage settings.

The audit adapter (softplc/adapters/audit) records into it; the HMI's export and `softplc audit`
read it. Plain storage code: nothing here listens to a running plant.
"""
