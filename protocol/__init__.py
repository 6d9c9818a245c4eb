"""(package: see docs/architecture.md)"""
