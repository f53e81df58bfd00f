"""Excitation, identification and tuning (chapter 5). The control process never imports this
package."""
